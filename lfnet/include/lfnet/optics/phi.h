// Coded acquisition: the measurement models Phi of docs/acquisition.md, behind one interface.
// The models, their parameters and normalisation are described in docs/acquisition.md.
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace lfnet::optics {

// The most views a Phi codes along each angular axis (light-field cameras and gantries have
// at most 17; Phi codes the central window).
constexpr int64_t kMaxViews = 64;

// Everything that defines a Phi; stored as JSON in every simulation, model and result.
struct PhiSpec {
  std::string name = "asp";  // asp, mask, aperture, random, lenslet
  int64_t n = 2;             // measurements per pixel, 1 .. U * V
  int64_t rows = 5;          // U: angular rows of the light field it codes
  int64_t cols = 5;          // V: angular columns
  int64_t frames = 1;        // T: sub-frames of one exposure (time-coded models; 1: a still camera)
  uint64_t seed = 0;         // for the random codes (mask, aperture, random)
  nlohmann::json params = nlohmann::json::object();  // model-specific parameters, resolved

  nlohmann::json to_json() const;
  // Strict: unknown keys and wrong types are ConfigErrors naming the JSON path. `params` are
  // checked when the model is built (make_phi), which also fills in their defaults.
  static PhiSpec from_json(const nlohmann::json& j, const std::string& path = "$");
  // Parses "asp", "asp:2", "mask:15", "exposure_aperture:1@4" (name[:N][@T]); N defaults to 2
  // and T, the sub-frames, to 1.
  static PhiSpec parse(const std::string& text);
  // "asp:2", or "exposure_aperture:1@4" when time-coded (the other fields are in to_json()).
  std::string label() const;
  // Angular rows of the light field the Phi takes: U, or T U for a time-coded one, whose
  // sequences are coded with their frames stacked along the rows (LightFieldSequence::stacked).
  int64_t coded_rows() const { return rows * frames; }

  bool operator==(const PhiSpec& other) const;
  bool operator!=(const PhiSpec& other) const { return !(*this == other); }
};

// Tikhonov weight of pinv_matrix by default: lambda = sigma^2 / tau^2 for noise sigma 0.01
// and a light-field prior of standard deviation tau = 0.3 (values in [0, 1]), at the scale
// every Phi is normalised to (a white light field measures 1 on average).
constexpr double kDefaultPinvLambda = 1e-3;

// A linear coded-capture operator. Light fields are single-channel (U, V, H, W) tensors, with
// optional leading batch dimensions (..., U, V, H, W) (e.g. colour channels); sensor images are
// (..., N, H, W): N measurement channels per pixel. float32 and float64 are supported.
// A patch's measurement vector is the (N, h, w) crop of the sensor image, flattened row-major
// (n, y, x): 81 N values for 9 x 9 patches; a light-field patch is flattened (u, v, y, x):
// 2025 values for 5 x 5 x 9 x 9.
class Phi {
 public:
  virtual ~Phi() = default;

  const PhiSpec& spec() const { return spec_; }
  int64_t measurements() const { return spec_.n; }
  // Angular rows of the light field it codes: U, or T U for a time-coded Phi (frames() > 1),
  // whose input is a sequence's stacked light field (C, T U, V, H, W).
  int64_t rows() const { return spec_.coded_rows(); }
  int64_t cols() const { return spec_.cols; }
  int64_t frames() const { return spec_.frames; }

  // Sensor image (..., N, H, W) of a light field (..., U, V, H, W), no sensor effects.
  virtual torch::Tensor forward(const torch::Tensor& lf) const = 0;
  // The exact adjoint: (..., N, H, W) -> (..., U, V, H, W), so <forward(x), y> = <x, adjoint(y)>.
  virtual torch::Tensor adjoint(const torch::Tensor& y) const = 0;

  // The operator restricted to the (h, w) patch at origin (y0, x0): a (N h w, U V h w) matrix
  // with patch_matrix(y0, x0) * vec(lf patch) = vec(forward(lf) crop). Origins need not be
  // multiples of period(). Throws ConfigError when no such matrix exists (random projections
  // off the block grid, or patch sizes that are not multiples of the block).
  virtual torch::Tensor patch_matrix(int64_t y0, int64_t x0, int64_t h, int64_t w,
                                     torch::ScalarType dtype = torch::kFloat32) const = 0;

  // Patch matrices of consistent origins that agree modulo period() are equal: 1 when the
  // same at every pixel (asp, aperture, random), the tile period for mask and lenslet.
  virtual int64_t period() const { return 1; }

  // Whether a patch at (y0, x0) has measurements that depend on that patch alone (false for
  // random projections off the block grid).
  virtual bool patch_consistent(int64_t /*y0*/, int64_t /*x0*/) const { return true; }

  // Whether every measurement at a pixel depends on that pixel's rays alone (all models but
  // random). Local models are described completely by pixel_weights().
  virtual bool local() const { return true; }

  // Side of the operator's smallest self-contained piece: 1 for local models (a pixel), the
  // block size for random.
  virtual int64_t block() const { return 1; }

  // The weights M_n(u, v) of the pixels of the (h, w) patch at (y0, x0): (N, U, V, h, w).
  // Local models only (throws otherwise).
  virtual torch::Tensor pixel_weights(int64_t y0, int64_t x0, int64_t h, int64_t w,
                                      torch::ScalarType dtype = torch::kFloat32) const;

  // Tikhonov-regularised pseudo-inverse of the patch matrix, (A^T A + lambda I)^-1 A^T, a
  // (U V h w, N h w) matrix computed in float64 through the SVD (per pixel for local models):
  // V diag(s / (s^2 + lambda)) U^T. At lambda = 0 singular values below 1e-12 s_max count as
  // zero (the Moore-Penrose pseudo-inverse).
  virtual torch::Tensor pinv_matrix(int64_t y0, int64_t x0, int64_t h, int64_t w,
                                    double lambda = kDefaultPinvLambda,
                                    torch::ScalarType dtype = torch::kFloat32) const;

 protected:
  explicit Phi(PhiSpec spec) : spec_(std::move(spec)) {}
  PhiSpec spec_;
};

// Scales a non-negative code (N, U, V, T, T) so a white light field measures 1 on average
// over one period (mean over n and the T x T pixels of sum_{u,v} M): the normalisation of every
// built-in model (docs/acquisition.md, "Normalisation"), differentiable in the code. A code that
// measures nothing of white is a NumericalError.
torch::Tensor normalise_white(const torch::Tensor& code);

// Builds a Phi from its spec; the result's spec() has every parameter resolved. Unknown names
// throw ConfigError listing the known ones; bad parameters throw ConfigError naming the path.
std::unique_ptr<Phi> make_phi(const PhiSpec& spec);

// Names of every registered model, sorted.
std::vector<std::string> phi_names();

// A factory of one model.
using PhiFactory = std::function<std::unique_ptr<Phi>(const PhiSpec& spec)>;

// Adds a model to the registry, replacing one of the same name (built-ins included). A
// `time_coded` factory builds specs of any frames T itself; any other is a still camera, built
// at T = 1 and, for frames > 1, held the same in every sub-frame.
void register_phi(const std::string& name, PhiFactory factory, bool time_coded = false);

// The still camera that a scene standing still sees through a time-coded `phi`: its sub-frames'
// weights summed (docs/video.md, "The still-scene baseline"). A still model over T sub-frames
// (asp:2@4) gives the model itself (asp:2); a still Phi is returned as it is. ConfigError for
// Phis that mix pixels.
std::unique_ptr<Phi> still_equivalent(const Phi& phi);

// Whether two local Phis weigh every ray of every pixel alike (to 1e-9 of the largest weight),
// whatever their specs say: a time-coded camera's still equivalent against a model's camera.
bool same_response(const Phi& a, const Phi& b);

// Whether the model `name` builds codes over sub-frames itself (register_phi's `time_coded`);
// false for still cameras and unknown names.
bool phi_is_time_coded(const std::string& name);

// Singular values of a Phi's self-contained pieces: how much each camera can recover.
struct PhiConditioning {
  std::string piece;              // "pixel" (local models) or "block" (random)
  int64_t piece_rows = 0;         // rows of each piece's matrix: N (pixel) or N b^2 (block)
  int64_t piece_cols = 0;         // columns: U V or U V b^2
  torch::Tensor singular_values;  // (pieces, min(rows, cols)) float64, descending; one piece
                                  // per pixel phase of a period (period^2) or one block
  torch::Tensor condition;        // (pieces,) s_max / s_min; inf when a piece is rank-deficient
  torch::Tensor rank;             // (pieces,) int64, singular values above 1e-10 s_max
};
PhiConditioning conditioning(const Phi& phi);

}  // namespace lfnet::optics
