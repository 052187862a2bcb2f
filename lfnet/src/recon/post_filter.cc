#include "lfnet/recon/post_filter.h"

#include <torch/torch.h>

#include <cmath>
#include <set>
#include <vector>

#include "lfnet/core/error.h"

namespace lfnet::recon {

namespace {

// The integer frequency bins (0..n-1) next to k n / period for k = 1 .. period - 1.
std::set<int64_t> lattice_bins(int64_t n, int64_t period) {
  std::set<int64_t> bins;
  for (int64_t k = 1; k < period; ++k) {
    const double f = static_cast<double>(k) * static_cast<double>(n) / static_cast<double>(period);
    bins.insert(static_cast<int64_t>(std::floor(f)) % n);
    bins.insert(static_cast<int64_t>(std::ceil(f)) % n);
  }
  bins.erase(0);
  return bins;
}

}  // namespace

torch::Tensor suppress_periodic(const torch::Tensor& lf, int64_t period) {
  LFNET_CHECK(lf.dim() == 5, "suppress_periodic expects (C, U, V, H, W), got ", lf.sizes());
  const int64_t h = lf.size(3), w = lf.size(4);
  if (period <= 1 || h < 2 * period || w < 2 * period) return lf;
  const auto ys = lattice_bins(h, period), xs = lattice_bins(w, period);
  // Lattice points: (y on the lattice or 0) x (x on the lattice or 0), except (0, 0).
  std::vector<int64_t> rows(ys.begin(), ys.end()), cols(xs.begin(), xs.end());
  rows.insert(rows.begin(), 0);
  cols.insert(cols.begin(), 0);
  auto on_lattice_y = [&](int64_t y) { return y == 0 || ys.count(y) > 0; };
  auto on_lattice_x = [&](int64_t x) { return x == 0 || xs.count(x) > 0; };

  const auto views = lf.to(torch::kFloat64).reshape({-1, h, w});
  auto spectrum = torch::fft::fft2(views);  // (views, H, W) complex128
  auto filtered = spectrum.clone();
  for (int64_t y : rows) {
    for (int64_t x : cols) {
      if (y == 0 && x == 0) continue;
      // The nearest neighbours that are not lattice bins themselves, one step out each way.
      std::vector<torch::Tensor> neighbours;
      const int64_t dy[4] = {-1, 1, 0, 0}, dx[4] = {0, 0, -1, 1};
      for (int d = 0; d < 4; ++d) {
        int64_t ny = y, nx = x;
        for (int step = 0; step < period; ++step) {
          ny = ((ny + dy[d]) % h + h) % h;
          nx = ((nx + dx[d]) % w + w) % w;
          if (dy[d] != 0 ? !on_lattice_y(ny) : !on_lattice_x(nx)) break;
        }
        if (!(ny == 0 && nx == 0)) neighbours.push_back(spectrum.select(1, ny).select(1, nx));
      }
      if (neighbours.empty()) continue;
      filtered.select(1, y).select(1, x).copy_(torch::stack(neighbours).mean(0));
    }
  }
  // The filtered spectrum stays Hermitian (the lattice and the neighbour rule are symmetric
  // under (y, x) -> (-y, -x)), so the inverse is real up to round-off.
  auto out = torch::real(torch::fft::ifft2(filtered));
  return out.reshape(lf.sizes()).to(lf.scalar_type());
}

}  // namespace lfnet::recon
