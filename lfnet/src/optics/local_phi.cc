// LocalPhi: forward and adjoint as one batched matrix product per pixel phase of the period.
#include <torch/torch.h>
// After torch.h: linalg.h alone does not declare Tensor.
#include <torch/linalg.h>

#include <algorithm>
#include <vector>

#include "lfnet/core/error.h"
#include "models.h"

namespace lfnet::optics::detail {

namespace {

// Product of the leading (batch) dimensions of a tensor whose last `keep` dims are its own.
int64_t lead_size(const torch::Tensor& t, int64_t keep) {
  int64_t b = 1;
  for (int64_t d = 0; d < t.dim() - keep; ++d) b *= t.size(d);
  return b;
}

std::vector<int64_t> lead_shape(const torch::Tensor& t, int64_t keep,
                                std::initializer_list<int64_t> tail) {
  auto shape = t.sizes().slice(0, t.dim() - keep).vec();
  shape.insert(shape.end(), tail);
  return shape;
}

// m (r, k) times each x[i] (k, p): (b, r, p). One plain matrix product per batch entry: a
// broadcast matmul of a small matrix against a wide one is several times slower here.
torch::Tensor batched_mm(const torch::Tensor& m, const torch::Tensor& x) {
  auto a = m.contiguous();
  auto out = torch::empty({x.size(0), a.size(0), x.size(2)}, x.options());
  for (int64_t i = 0; i < x.size(0); ++i) {
    auto slot = out[i];
    torch::mm_out(slot, a, x[i]);
  }
  return out;
}

// (b, c, H, W) -> (T * T, c, b * Hb * Wb) with the pixel phase (y mod T, x mod T) first;
// zero-padded up to multiples of T.
torch::Tensor to_phases(const torch::Tensor& x, int64_t t) {
  const int64_t b = x.size(0), c = x.size(1), h = x.size(2), w = x.size(3);
  const int64_t hb = (h + t - 1) / t, wb = (w + t - 1) / t;
  auto padded = x;
  if (hb * t != h || wb * t != w)
    padded = torch::constant_pad_nd(x, {0, wb * t - w, 0, hb * t - h});
  return padded.view({b, c, hb, t, wb, t})
      .permute({3, 5, 1, 0, 2, 4})
      .reshape({t * t, c, b * hb * wb});
}

// The inverse of to_phases: (T * T, c, b * Hb * Wb) -> (b, c, H, W).
torch::Tensor from_phases(const torch::Tensor& p, int64_t t, int64_t b, int64_t h, int64_t w) {
  const int64_t c = p.size(1), hb = (h + t - 1) / t, wb = (w + t - 1) / t;
  auto x = p.view({t, t, c, b, hb, wb}).permute({3, 2, 4, 0, 5, 1}).reshape({b, c, hb * t, wb * t});
  if (hb * t != h || wb * t != w) x = x.slice(2, 0, h).slice(3, 0, w);
  return x;
}

// Rows per band of a banded forward or adjoint: a multiple of the period T (so each band
// starts at phase 0) holding about 2^23 values of the wider side, or every row when they fit.
int64_t band_rows(int64_t values_per_row, int64_t t, int64_t h) {
  constexpr int64_t kBandValues = int64_t{1} << 23;
  const int64_t rows = std::max<int64_t>(1, kBandValues / std::max<int64_t>(1, values_per_row));
  return std::min(h, std::max(t, rows / t * t));
}

// Applies `op` (a forward or adjoint of whole rows) to bands of rows of `x` (..., H, W) into a
// tensor of `out_shape`: the phase-major copies then hold one band at a time, not the image.
template <typename Op>
torch::Tensor banded(const torch::Tensor& x, int64_t rows, const std::vector<int64_t>& out_shape,
                     const Op& op) {
  const int64_t h = x.size(-2);
  if (rows >= h) return op(x);
  auto out = torch::empty(out_shape, x.options());
  for (int64_t y0 = 0; y0 < h; y0 += rows) {
    const int64_t n = std::min(rows, h - y0);
    out.narrow(-2, y0, n).copy_(op(x.narrow(-2, y0, n)));
  }
  return out;
}

}  // namespace

void check_light_field(const torch::Tensor& lf, const PhiSpec& spec) {
  LFNET_CHECK(lf.defined() && lf.dim() >= 4, "Phi '", spec.label(),
              "' expects a light field (..., U, V, H, W), got a tensor of rank ",
              lf.defined() ? lf.dim() : 0);
  LFNET_CHECK(lf.size(-4) == spec.coded_rows() && lf.size(-3) == spec.cols, "Phi '", spec.label(),
              "' codes ", spec.coded_rows(), "x", spec.cols,
              spec.frames > 1 ? " views (its frames stacked along the rows)" : " views",
              ", but the light field has ", lf.size(-4), "x", lf.size(-3));
  LFNET_CHECK(lf.scalar_type() == torch::kFloat32 || lf.scalar_type() == torch::kFloat64,
              "Phi expects float32 or float64 light fields");
}

void check_sensor(const torch::Tensor& y, const PhiSpec& spec) {
  LFNET_CHECK(y.defined() && y.dim() >= 3, "Phi '", spec.label(),
              "' expects a sensor image (..., N, H, W)");
  LFNET_CHECK(y.size(-3) == spec.n, "Phi '", spec.label(), "' has ", spec.n,
              " measurements per pixel, but the sensor image has ", y.size(-3));
  LFNET_CHECK(y.scalar_type() == torch::kFloat32 || y.scalar_type() == torch::kFloat64,
              "Phi expects float32 or float64 sensor images");
}

torch::Tensor tikhonov_pinv(const torch::Tensor& a, double lambda) {
  LFNET_CHECK(lambda >= 0, "the Tikhonov weight lambda must be >= 0, got ", lambda);
  auto [u, s, vh] =
      torch::linalg::svd(a.to(torch::kFloat64), /*full_matrices=*/false, c10::nullopt);
  auto smax = s.amax(-1, /*keepdim=*/true);
  auto f = s / (s * s + lambda);
  f = torch::where(s > 1e-12 * smax, f, torch::zeros_like(f));
  return torch::matmul(vh.transpose(-2, -1) * f.unsqueeze(-2), u.transpose(-2, -1));
}

void check_code_size(const PhiSpec& spec, int64_t values, const std::string& what) {
  constexpr int64_t kMaxValues = int64_t{1} << 27;
  LFNET_CHECK_AS(ConfigError, values <= kMaxValues, "Phi '", spec.label(), "' on ",
                 spec.coded_rows(), "x", spec.cols, " views needs ", what, " of ", values,
                 " values, more than the 2^27 lfnet builds: use fewer views, measurements or a "
                 "smaller period");
}

LocalPhi::LocalPhi(PhiSpec spec, const torch::Tensor& code) : Phi(std::move(spec)) {
  LFNET_CHECK(code.dim() == 5 && code.size(0) == spec_.n && code.size(1) == rows() &&
                  code.size(2) == spec_.cols && code.size(3) == code.size(4),
              "internal: a local Phi code must be (N, U, V, T, T)");
  code_ = code.to(torch::kFloat64).contiguous();
  code32_ = code_.to(torch::kFloat32);
}

torch::Tensor LocalPhi::phase_matrices(torch::ScalarType dtype) const {
  const auto& c = dtype == torch::kFloat64 ? code_ : code32_;
  const int64_t t = period();
  return c.permute({3, 4, 0, 1, 2}).reshape({t * t, spec_.n, rows() * spec_.cols});
}

torch::Tensor LocalPhi::forward(const torch::Tensor& lf) const {
  check_light_field(lf, spec_);
  const int64_t n = spec_.n, uv = rows() * spec_.cols, t = period();
  const int64_t h = lf.size(-2), w = lf.size(-1), b = lead_size(lf, 4);
  auto mats = phase_matrices(lf.scalar_type());
  auto op = [&](const torch::Tensor& x) {
    const int64_t xh = x.size(-2);
    torch::Tensor y;
    if (t == 1) {
      y = batched_mm(mats[0], x.reshape({b, uv, xh * w}));
    } else {
      y = from_phases(torch::bmm(mats, to_phases(x.reshape({b, uv, xh, w}), t)), t, b, xh, w);
    }
    return y.reshape(lead_shape(x, 4, {n, xh, w})).contiguous();
  };
  return banded(lf, band_rows(b * uv * w, t, h), lead_shape(lf, 4, {n, h, w}), op);
}

torch::Tensor LocalPhi::adjoint(const torch::Tensor& y) const {
  check_sensor(y, spec_);
  const int64_t n = spec_.n, uv = rows() * spec_.cols, t = period();
  const int64_t h = y.size(-2), w = y.size(-1), b = lead_size(y, 3);
  auto mats = phase_matrices(y.scalar_type()).transpose(1, 2).contiguous();
  auto op = [&](const torch::Tensor& s) {
    const int64_t sh = s.size(-2);
    torch::Tensor x;
    if (t == 1) {
      x = batched_mm(mats[0], s.reshape({b, n, sh * w}));
    } else {
      x = from_phases(torch::bmm(mats, to_phases(s.reshape({b, n, sh, w}), t)), t, b, sh, w);
    }
    return x.reshape(lead_shape(s, 3, {rows(), spec_.cols, sh, w})).contiguous();
  };
  return banded(y, band_rows(b * uv * w, t, h), lead_shape(y, 3, {rows(), spec_.cols, h, w}), op);
}

torch::Tensor LocalPhi::pixel_weights(int64_t y0, int64_t x0, int64_t h, int64_t w,
                                      torch::ScalarType dtype) const {
  LFNET_CHECK(y0 >= 0 && x0 >= 0 && h >= 1 && w >= 1, "patch at (", y0, ", ", x0, ") of ", h, "x",
              w, ": origins must be >= 0 and sizes >= 1");
  const int64_t t = period();
  auto iy = (torch::arange(h, torch::kLong) + y0).remainder(t);
  auto ix = (torch::arange(w, torch::kLong) + x0).remainder(t);
  return code_.index_select(3, iy).index_select(4, ix).to(dtype);
}

torch::Tensor LocalPhi::patch_matrix(int64_t y0, int64_t x0, int64_t h, int64_t w,
                                     torch::ScalarType dtype) const {
  auto weights = pixel_weights(y0, x0, h, w, dtype);  // (N, U, V, h, w)
  auto opts = torch::TensorOptions().dtype(dtype);
  // A[n, y, x, u, v, Y, X] = M[n, u, v, y, x] [y == Y] [x == X]
  auto a =
      torch::einsum("nuvyx,yY,xX->nyxuvYX", {weights, torch::eye(h, opts), torch::eye(w, opts)});
  return a.reshape({spec_.n * h * w, rows() * spec_.cols * h * w});
}

torch::Tensor LocalPhi::pinv_matrix(int64_t y0, int64_t x0, int64_t h, int64_t w, double lambda,
                                    torch::ScalarType dtype) const {
  auto weights = pixel_weights(y0, x0, h, w, torch::kFloat64);  // (N, U, V, h, w)
  const int64_t n = spec_.n, uv = rows() * spec_.cols;
  auto per_pixel = weights.permute({3, 4, 0, 1, 2}).reshape({h * w, n, uv});
  auto pinv = tikhonov_pinv(per_pixel, lambda).view({h, w, uv, n});  // (h, w, UV, N)
  auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  auto b = torch::einsum("yxkn,yY,xX->kyxnYX", {pinv, torch::eye(h, opts), torch::eye(w, opts)});
  return b.reshape({uv * h * w, n * h * w}).to(dtype);
}

}  // namespace lfnet::optics::detail
