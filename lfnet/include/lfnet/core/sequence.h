// A light-field sequence: T sub-frames of one light field each, the input of time-coded cameras
// (docs/video.md).
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <string>
#include <vector>

#include "lfnet/core/light_field.h"

namespace lfnet {

// The most sub-frames of one exposure: of a sequence, a time-coded Phi and render_sequence.
constexpr int64_t kMaxFrames = 64;

// The folder of frame t of a sequence folder: DIR/frame_t (docs/video.md).
std::string sequence_frame_dir(const std::string& dir, int64_t t);

// T light fields of one shape, float32 in [0, 1], held as one (T, C, U, V, H, W) tensor: frame
// t is the light field (C, U, V, H, W) of sub-frame t within the exposure.
class LightFieldSequence {
 public:
  LightFieldSequence() = default;
  // Takes a (T, C, U, V, H, W) tensor; converts it to contiguous float32.
  explicit LightFieldSequence(const torch::Tensor& data);
  // The frames in order; they must share one shape (a ConfigError names the first that does not).
  explicit LightFieldSequence(const std::vector<LightField>& frames);

  const torch::Tensor& data() const { return data_; }
  bool defined() const { return data_.defined(); }

  int64_t frames() const { return data_.size(0); }  // T
  int64_t channels() const { return data_.size(1); }
  int64_t rows() const { return data_.size(2); }  // U
  int64_t cols() const { return data_.size(3); }  // V
  int64_t height() const { return data_.size(4); }
  int64_t width() const { return data_.size(5); }

  // Sub-frame t (0-based) as a light field (not a copy).
  LightField frame(int64_t t) const;

  // The frames' views stacked along the angular rows: a (C, T U, V, H, W) light field whose rows
  // [t U, (t + 1) U) are frame t's. It is the layout time-coded Phis take
  // (docs/acquisition.md, "Time-coded cameras"), so every patch and pinv routine reads it as is.
  LightField stacked() const;
  // The inverse of stacked(): a (C, T U, V, H, W) light field as T frames of U rows.
  static LightFieldSequence unstack(const LightField& stacked, int64_t frames);

  // Every frame's luma (LightField::grey).
  LightFieldSequence grey() const;
  // Every frame's central n x n views (LightField::central).
  LightFieldSequence central(int64_t n) const;
  // The mean over time: what a still camera's exposure integrates, as one light field.
  LightField time_mean() const;
  // "TxCxUxVxHxW" for messages.
  std::string shape_string() const;

 private:
  torch::Tensor data_;
};

// Synthetic motion of a still light field, for testing video methods on real captures
// (docs/video.md, "Synthetic motion"): T frames in which the whole image moves by (dx, dy)
// px per sub-frame (integers: no resampling) and, with `walk` > 0, the camera moves sideways by
// `walk` views per sub-frame, so each point moves by its own disparity times `walk` (real
// parallax, not a model of it). Frames are cropped so that nothing wraps: H - |dy| (T - 1) x
// W - |dx| (T - 1) pixels and V - walk (T - 1) view columns. ConfigError when nothing is left.
struct SyntheticMotion {
  int64_t dx = 0;    // px per sub-frame, rightwards
  int64_t dy = 0;    // px per sub-frame, downwards
  int64_t walk = 0;  // view columns per sub-frame
};
LightFieldSequence synthetic_motion(const LightField& lf, int64_t frames,
                                    const SyntheticMotion& motion);

}  // namespace lfnet
