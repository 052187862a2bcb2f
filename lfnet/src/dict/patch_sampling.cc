#include "lfnet/dict/patch_sampling.h"

#include <torch/torch.h>

#include <cmath>
#include <random>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"

namespace lfnet::dict {

void PatchSamplingOptions::validate() const {
  LFNET_CHECK_AS(ConfigError, count >= 1, "sampling.count must be >= 1, got ", count);
  LFNET_CHECK_AS(ConfigError, views >= 1, "sampling.views must be >= 1, got ", views);
  LFNET_CHECK_AS(ConfigError, patch_size >= 1, "sampling.patch_size must be >= 1, got ",
                 patch_size);
  LFNET_CHECK_AS(ConfigError, std::isfinite(min_variance) && min_variance >= 0.0,
                 "sampling.min_variance must be >= 0, got ", min_variance);
  LFNET_CHECK_AS(ConfigError, max_draws >= 1, "sampling.max_draws must be >= 1, got ", max_draws);
}

nlohmann::json PatchSamplingOptions::to_json() const { return fields_to_json(*this); }

PatchSamplingOptions PatchSamplingOptions::from_json(const nlohmann::json& j,
                                                     const std::string& path) {
  PatchSamplingOptions o;
  JsonReader r(j, path);
  read_fields(r, o);
  r.finish();
  try {
    o.validate();
  } catch (const ConfigError& e) {
    throw ConfigError(path + ": " + e.what());
  }
  return o;
}

torch::Tensor sample_patches(const std::vector<LightField>& light_fields,
                             const PatchSamplingOptions& options, PatchSamplingStats* stats) {
  options.validate();
  LFNET_CHECK_AS(ConfigError, !light_fields.empty(), "sample_patches: no light fields given");
  const int64_t p = options.patch_size, n = options.views;
  std::vector<torch::Tensor> sources;  // (C, n, n, H, W) each
  std::vector<uint64_t> cumulative;    // patch positions (times channels) up to and with each
  uint64_t total = 0;
  for (size_t i = 0; i < light_fields.size(); ++i) {
    const auto& lf = light_fields[i];
    LFNET_CHECK_AS(ConfigError, lf.defined(), "sample_patches: light field ", i, " is empty");
    LFNET_CHECK_AS(ConfigError, lf.rows() >= n && lf.cols() >= n, "sample_patches: light field ", i,
                   " has ", lf.rows(), "x", lf.cols(), " views, fewer than ", n, "x", n);
    LFNET_CHECK_AS(ConfigError, lf.height() >= p && lf.width() >= p, "sample_patches: light field ",
                   i, " (", lf.shape_string(), ") is smaller than a ", p, "x", p, " patch");
    LightField src = (options.color ? lf : lf.grey()).central(n);
    sources.push_back(src.data().contiguous());
    total += static_cast<uint64_t>(src.channels() * (src.height() - p + 1) * (src.width() - p + 1));
    cumulative.push_back(total);
  }
  const int64_t dim = n * n * p * p;
  auto out = torch::empty({options.count, dim}, torch::kFloat32);
  std::mt19937_64 rng(options.seed);
  PatchSamplingStats st;
  int64_t kept = 0;
  const int64_t budget = options.count * options.max_draws;
  while (kept < options.count && st.drawn < budget) {
    uint64_t r = rng() % total;
    size_t which = 0;
    while (r >= cumulative[which]) ++which;
    if (which > 0) r -= cumulative[which - 1];
    const auto& src = sources[which];
    const auto ny = static_cast<uint64_t>(src.size(axis::kH) - p + 1);
    const auto nx = static_cast<uint64_t>(src.size(axis::kW) - p + 1);
    const auto x0 = static_cast<int64_t>(r % nx);
    const auto y0 = static_cast<int64_t>((r / nx) % ny);
    const auto c = static_cast<int64_t>(r / (nx * ny));
    auto patch = src[c].narrow(2, y0, p).narrow(3, x0, p).reshape({dim});
    ++st.drawn;
    if (options.min_variance > 0.0 &&
        patch.to(torch::kFloat64).var(/*unbiased=*/false).item<double>() < options.min_variance) {
      ++st.dropped;
      continue;
    }
    out[kept++].copy_(patch);
  }
  if (stats) *stats = st;
  LFNET_CHECK_AS(Error, kept == options.count, "sample_patches: only ", kept, " of ", options.count,
                 " patches have variance >= ", options.min_variance, " after ", st.drawn,
                 " draws; lower sampling.min_variance or add light fields");
  return out;
}

}  // namespace lfnet::dict
