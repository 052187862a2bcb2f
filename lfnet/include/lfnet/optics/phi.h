// Coded acquisition: the measurement models Phi of DESIGN section 2, behind one interface.
#pragma once

#include <nlohmann/json.hpp>
#include <torch/types.h>

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace lfnet::optics {

// Everything that defines a Phi; stored as JSON in every simulation, model and result.
struct PhiSpec {
  std::string name = "asp";  // asp, mask, aperture, random, lenslet
  int64_t n = 2;             // measurements per pixel, 1 .. U * V
  int64_t rows = 5;          // U: angular rows of the light field it codes
  int64_t cols = 5;          // V: angular columns
  uint64_t seed = 0;         // for the random codes (mask, aperture, random)
  nlohmann::json params = nlohmann::json::object();  // model-specific parameters, resolved

  nlohmann::json to_json() const;
  static PhiSpec from_json(const nlohmann::json& j, const std::string& path = "$");
  // Parses "asp", "asp:2", "mask:15" (name[:N]).
  static PhiSpec parse(const std::string& text);
};

// A linear coded-capture operator. Light fields are single-channel (U, V, H, W) tensors;
// sensor images are (N, H, W): N measurement channels per pixel. A patch's measurement vector
// is the (N, h, w) crop of the sensor image, flattened row-major (n, y, x): 81 N values for
// 9 x 9 patches; a light-field patch is flattened (u, v, y, x): 2025 values for 5 x 5 x 9 x 9.
class Phi {
 public:
  virtual ~Phi() = default;

  const PhiSpec& spec() const { return spec_; }
  int64_t measurements() const { return spec_.n; }

  // Sensor image (N, H, W) of a light field (U, V, H, W), no sensor effects.
  virtual torch::Tensor forward(const torch::Tensor& lf) const = 0;
  // The exact adjoint: (N, H, W) -> (U, V, H, W), so <forward(x), y> = <x, adjoint(y)>.
  virtual torch::Tensor adjoint(const torch::Tensor& y) const = 0;

  // The operator restricted to the (h, w) patch at origin (y0, x0): a (N h w, U V h w) matrix
  // with patch_matrix(y0, x0) * vec(lf patch) = vec(forward(lf) crop). Throws when no such
  // matrix exists (random projections at origins that are not block-aligned).
  virtual torch::Tensor patch_matrix(int64_t y0, int64_t x0, int64_t h, int64_t w) const = 0;

  // Patch matrices repeat with this period in y0 and x0 (1 when the same at every pixel).
  virtual int64_t period() const { return 1; }

  // Whether a patch at (y0, x0) has measurements that depend on that patch alone (false for
  // random projections off the block grid).
  virtual bool patch_consistent(int64_t y0, int64_t x0) const { return true; }

 protected:
  explicit Phi(PhiSpec spec) : spec_(std::move(spec)) {}
  PhiSpec spec_;
};

// Builds a Phi from its spec. Unknown names throw ConfigError listing the known ones.
std::unique_ptr<Phi> make_phi(const PhiSpec& spec);

// Names of every registered model.
std::vector<std::string> phi_names();

}  // namespace lfnet::optics
