#include "lfnet/core/view_noise.h"

#include <torch/torch.h>

#include "lfnet/core/error.h"

namespace lfnet {

torch::Tensor view_noise(torch::IntArrayRef sizes, int64_t angular_radius, int64_t spatial_radius,
                         at::Generator generator) {
  LFNET_CHECK(sizes.size() == 5, "view_noise: expected sizes (C, U, V, H, W)");
  LFNET_CHECK(angular_radius >= 0 && spatial_radius >= 0, "view_noise: negative radius");
  const int64_t c = sizes[0], u = sizes[1], v = sizes[2], h = sizes[3], w = sizes[4];
  if (angular_radius == 0 && spatial_radius == 0) return at::normal(0.0, 1.0, sizes, generator);
  // Correlated noise is shared by the colours too: the views were demosaiced together.
  auto n = at::normal(0.0, 1.0, {1, u, v, h, w}, generator);
  namespace F = torch::nn::functional;
  if (angular_radius > 0) {
    const int64_t k = 2 * angular_radius + 1;
    // (C H W, 1, U, V): each view the mean of the views around it that the grid has.
    auto a = n.permute({0, 3, 4, 1, 2}).reshape({h * w, 1, u, v});
    a = F::avg_pool2d(
        a, F::AvgPool2dFuncOptions(k).stride(1).padding(angular_radius).count_include_pad(false));
    n = a.reshape({1, h, w, u, v}).permute({0, 3, 4, 1, 2}).contiguous();
  }
  if (spatial_radius > 0) {
    const int64_t k = 2 * spatial_radius + 1;
    auto s = n.reshape({u * v, 1, h, w});
    s = F::avg_pool2d(
        s, F::AvgPool2dFuncOptions(k).stride(1).padding(spatial_radius).count_include_pad(false));
    n = s.reshape({1, u, v, h, w});
  }
  const double sd = n.std().item<double>();
  return (sd > 0 ? n / sd : n).expand({c, u, v, h, w}).contiguous();
}

}  // namespace lfnet
