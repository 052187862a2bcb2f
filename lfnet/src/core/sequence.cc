#include "lfnet/core/sequence.h"

#include <cstdlib>
#include <sstream>

#include "lfnet/core/error.h"

namespace lfnet {

namespace {
constexpr int64_t kSequenceRank = axis::kRank + 1;
}  // namespace

LightFieldSequence::LightFieldSequence(const torch::Tensor& data) {
  LFNET_CHECK(data.defined() && data.dim() == kSequenceRank && data.size(0) > 0,
              "a light-field sequence needs a tensor of shape (T, C, U, V, H, W), T >= 1");
  LFNET_CHECK(data.size(1) == 1 || data.size(1) == 3,
              "a light-field sequence has 1 or 3 channels, got ", data.size(1));
  data_ = data.to(torch::kFloat32).contiguous();
}

LightFieldSequence::LightFieldSequence(const std::vector<LightField>& frames) {
  LFNET_CHECK_AS(ConfigError, !frames.empty(), "a light-field sequence needs at least one frame");
  std::vector<torch::Tensor> data;
  data.reserve(frames.size());
  for (size_t t = 0; t < frames.size(); ++t) {
    LFNET_CHECK_AS(ConfigError, frames[t].data().sizes() == frames[0].data().sizes(), "frame ", t,
                   " is ", frames[t].shape_string(), " but frame 0 is ", frames[0].shape_string());
    data.push_back(frames[t].data());
  }
  data_ = torch::stack(data).contiguous();
}

LightField LightFieldSequence::frame(int64_t t) const {
  LFNET_CHECK(t >= 0 && t < frames(), "frame ", t, " outside a sequence of ", frames());
  return LightField(data_[t]);
}

LightField LightFieldSequence::stacked() const {
  // (T, C, U, ...) -> (C, T, U, ...) -> (C, T U, ...).
  return LightField(
      data_.transpose(0, 1).reshape({channels(), frames() * rows(), cols(), height(), width()}));
}

LightFieldSequence LightFieldSequence::unstack(const LightField& stacked, int64_t frames) {
  LFNET_CHECK(frames >= 1 && stacked.rows() % frames == 0, "cannot split ", stacked.rows(),
              " angular rows into ", frames, " frames");
  const auto& d = stacked.data();
  return LightFieldSequence(d.reshape({d.size(axis::kC), frames, d.size(axis::kU) / frames,
                                       d.size(axis::kV), d.size(axis::kH), d.size(axis::kW)})
                                .transpose(0, 1));
}

LightFieldSequence LightFieldSequence::grey() const {
  if (channels() == 1) return *this;
  std::vector<LightField> out;
  for (int64_t t = 0; t < frames(); ++t) out.push_back(frame(t).grey());
  return LightFieldSequence(out);
}

LightFieldSequence LightFieldSequence::central(int64_t n) const {
  std::vector<LightField> out;
  for (int64_t t = 0; t < frames(); ++t) out.push_back(frame(t).central(n));
  return LightFieldSequence(out);
}

LightField LightFieldSequence::time_mean() const { return LightField(data_.mean(0)); }

std::string sequence_frame_dir(const std::string& dir, int64_t t) {
  std::string out = dir;
  if (!out.empty() && out.back() != '/') out += '/';
  return out + "frame_" + std::to_string(t);
}

std::string LightFieldSequence::shape_string() const {
  if (!defined()) return "(empty)";
  std::ostringstream s;
  s << frames() << "x" << channels() << "x" << rows() << "x" << cols() << "x" << height() << "x"
    << width();
  return s.str();
}

LightFieldSequence synthetic_motion(const LightField& lf, int64_t frames,
                                    const SyntheticMotion& motion) {
  LFNET_CHECK_AS(ConfigError, frames >= 1, "a sequence has at least one frame, got ", frames);
  LFNET_CHECK_AS(ConfigError, motion.walk >= 0,
                 "the camera walks a non-negative number of views "
                 "per sub-frame, got ",
                 motion.walk);
  const int64_t span = frames - 1;
  const int64_t h = lf.height() - std::abs(motion.dy) * span;
  const int64_t w = lf.width() - std::abs(motion.dx) * span;
  const int64_t cols = lf.cols() - motion.walk * span;
  LFNET_CHECK_AS(ConfigError, h >= 1 && w >= 1 && cols >= 1, "motion of (", motion.dx, ", ",
                 motion.dy, ") px and ", motion.walk, " views per sub-frame over ", frames,
                 " sub-frames leaves nothing of a ", lf.shape_string(), " light field");
  // Content moving right by dx is the crop moving left: sub-frame t's crop starts dx t before
  // the first one's.
  const int64_t y_first = motion.dy > 0 ? motion.dy * span : 0;
  const int64_t x_first = motion.dx > 0 ? motion.dx * span : 0;
  std::vector<LightField> out;
  for (int64_t t = 0; t < frames; ++t) {
    const int64_t y0 = y_first - motion.dy * t, x0 = x_first - motion.dx * t;
    out.emplace_back(lf.data()
                         .narrow(axis::kV, motion.walk * t, cols)
                         .narrow(axis::kH, y0, h)
                         .narrow(axis::kW, x0, w));
  }
  return LightFieldSequence(out);
}

}  // namespace lfnet
