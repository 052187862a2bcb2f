// Ideal random projections: one dense matrix applied to every non-overlapping b x b block.
#include "lfnet/core/error.h"
#include "lfnet/optics/counter_rng.h"
#include "models.h"

namespace lfnet::optics::detail {

namespace {

// The random model. Borders: the light field is zero-padded up to whole blocks, every block
// is measured and the sensor keeps the measurements of its own pixels, so a partial border
// block is the full-block matrix restricted to the rows and columns that exist. This is a
// plain linear operator (crop . R . pad) with the exact adjoint (crop . R^T . pad).
class RandomPhi : public Phi {
 public:
  RandomPhi(PhiSpec spec, torch::Tensor matrix, int64_t block)
      : Phi(std::move(spec)), matrix_(std::move(matrix)), block_(block) {
    matrix32_ = matrix_.to(torch::kFloat32);
  }

  torch::Tensor forward(const torch::Tensor& lf) const override {
    check_light_field(lf, spec_);
    const int64_t uv = spec_.rows * spec_.cols;
    const int64_t h = lf.size(-2), w = lf.size(-1);
    auto lead = lf.sizes().slice(0, lf.dim() - 4).vec();
    auto blocks = to_blocks(lf.reshape({-1, uv, h, w}));
    auto y = torch::matmul(blocks, matrix_for(lf.scalar_type()).t());
    auto out = from_blocks(y, spec_.n, lf.numel() / (uv * h * w), h, w);
    lead.insert(lead.end(), {spec_.n, h, w});
    return out.reshape(lead).contiguous();
  }

  torch::Tensor adjoint(const torch::Tensor& y) const override {
    check_sensor(y, spec_);
    const int64_t uv = spec_.rows * spec_.cols;
    const int64_t h = y.size(-2), w = y.size(-1), b = y.numel() / (spec_.n * h * w);
    auto lead = y.sizes().slice(0, y.dim() - 3).vec();
    auto blocks = to_blocks(y.reshape({b, spec_.n, h, w}));
    auto x = torch::matmul(blocks, matrix_for(y.scalar_type()));
    auto out = from_blocks(x, uv, b, h, w);
    lead.insert(lead.end(), {spec_.rows, spec_.cols, h, w});
    return out.reshape(lead).contiguous();
  }

  torch::Tensor patch_matrix(int64_t y0, int64_t x0, int64_t h, int64_t w,
                             torch::ScalarType dtype) const override {
    const int64_t b = block_;
    LFNET_CHECK_AS(ConfigError,
                   patch_consistent(y0, x0) && h % b == 0 && w % b == 0 && h > 0 && w > 0,
                   "random projections mix the pixels of each ", b, "x", b,
                   " block: a patch matrix exists only for patches on the block grid (origins and "
                   "sizes multiples of ",
                   b, "), not for a ", h, "x", w, " patch at (", y0, ", ", x0,
                   "); use per_patch mode or a stride and patch size that are multiples of ", b);
    const int64_t n = spec_.n, u = spec_.rows, v = spec_.cols;
    auto a = torch::zeros({n, h, w, u, v, h, w}, torch::TensorOptions().dtype(dtype));
    auto r = matrix_for(dtype).view({n, b, b, u, v, b, b});
    for (int64_t i = 0; i < h / b; ++i) {
      for (int64_t j = 0; j < w / b; ++j) {
        a.slice(1, i * b, (i + 1) * b)
            .slice(2, j * b, (j + 1) * b)
            .slice(5, i * b, (i + 1) * b)
            .slice(6, j * b, (j + 1) * b)
            .copy_(r);
      }
    }
    return a.view({n * h * w, u * v * h * w});
  }

  bool patch_consistent(int64_t y0, int64_t x0) const override {
    return y0 % block_ == 0 && x0 % block_ == 0;
  }
  bool local() const override { return false; }
  int64_t block() const override { return block_; }

 private:
  const torch::Tensor& matrix_for(torch::ScalarType dtype) const {
    return dtype == torch::kFloat64 ? matrix_ : matrix32_;
  }

  // (B, c, H, W) -> (B * Hb * Wb, c * b * b), zero-padded to whole blocks.
  torch::Tensor to_blocks(const torch::Tensor& x) const {
    const int64_t bsz = x.size(0), c = x.size(1), h = x.size(2), w = x.size(3), b = block_;
    const int64_t hb = (h + b - 1) / b, wb = (w + b - 1) / b;
    auto padded = x;
    if (hb * b != h || wb * b != w)
      padded = torch::constant_pad_nd(x, {0, wb * b - w, 0, hb * b - h});
    return padded.view({bsz, c, hb, b, wb, b})
        .permute({0, 2, 4, 1, 3, 5})
        .reshape({bsz * hb * wb, c * b * b});
  }

  // (B * Hb * Wb, c * b * b) -> (B, c, H, W), cropping the padding.
  torch::Tensor from_blocks(const torch::Tensor& x, int64_t c, int64_t bsz, int64_t h,
                            int64_t w) const {
    const int64_t b = block_, hb = (h + b - 1) / b, wb = (w + b - 1) / b;
    auto out = x.view({bsz, hb, wb, c, b, b})
                   .permute({0, 3, 1, 4, 2, 5})
                   .reshape({bsz, c, hb * b, wb * b});
    if (hb * b != h || wb * b != w) out = out.slice(2, 0, h).slice(3, 0, w);
    return out;
  }

  torch::Tensor matrix_;    // (N b b, U V b b) float64
  torch::Tensor matrix32_;  // the same in float32
  int64_t block_;
};

}  // namespace

std::unique_ptr<Phi> make_random(const PhiSpec& spec) {
  JsonReader r(spec.params, "$.params");
  int64_t block = 9;                      // b: side of the blocks (the patch size)
  std::string distribution = "gaussian";  // "gaussian" N(0, 1) or "bernoulli" +-1 entries
  r.get("block", block);
  r.get("distribution", distribution);
  r.finish();
  LFNET_CHECK_AS(ConfigError, block >= 1 && block <= 32, r.path_of("block"),
                 ": the block size must be in 1..32, got ", block);
  LFNET_CHECK_AS(ConfigError, distribution == "gaussian" || distribution == "bernoulli",
                 r.path_of("distribution"), ": expected \"gaussian\" or \"bernoulli\", got \"",
                 distribution, "\"");
  const int64_t rows = spec.n * block * block, cols = spec.rows * spec.cols * block * block;
  check_code_size(spec, rows * cols, "a block matrix");
  const CounterRng rng(spec.seed, stream::kRandomMatrix);
  auto m = torch::empty({rows, cols}, torch::kFloat64);
  double* p = m.data_ptr<double>();
  const bool gaussian = distribution == "gaussian";
  at::parallel_for(0, rows * cols, 4096, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const auto k = static_cast<uint64_t>(i);
      p[i] = gaussian ? rng.normal(k) : ((rng.bits(k) >> 63) != 0U ? 1.0 : -1.0);
    }
  });
  // Rows get the mean norm of the asp rows at the same N (docs/acquisition.md), of the table
  // whose first pair has phase 0 (the random model's scale is fixed by it, whatever asp's
  // default pair).
  PhiSpec asp_spec = spec;
  asp_spec.name = "asp";
  AspParams reference;
  reference.pair_alpha = 0.0;
  auto asp = asp_weights(asp_spec, reference).view({spec.n, -1});
  const double target = asp.norm(2, {1}).mean().item<double>();
  m *= target / m.norm(2, {1}).mean().item<double>();
  PhiSpec resolved = spec;
  resolved.params = {{"block", block}, {"distribution", distribution}};
  return std::make_unique<RandomPhi>(resolved, m, block);
}

}  // namespace lfnet::optics::detail
