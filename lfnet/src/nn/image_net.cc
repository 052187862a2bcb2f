#include "lfnet/nn/image_net.h"

#include <torch/torch.h>

#include <algorithm>
#include <string>

#include "lfnet/core/error.h"
#include "lfnet/core/fields.h"

namespace lfnet::nn {

void ImageNetOptions::read(JsonReader& reader) { read_fields(reader, *this); }
nlohmann::json ImageNetOptions::to_json() const { return fields_to_json(*this); }

void ImageNetOptions::validate(const std::string& key) const {
  const std::string at = key.empty() ? key : key + ".";
  if (channels < 1) throw ConfigError(at + "channels: must be positive");
  if (levels < 1 || levels > 6) throw ConfigError(at + "levels: must be 1 to 6");
  if (blocks < 1) throw ConfigError(at + "blocks: must be >= 1");
  if (widths.empty()) return;
  if (static_cast<int64_t>(widths.size()) != levels) {
    throw ConfigError(at + "widths: has " + std::to_string(widths.size()) + " entries for " + at +
                      "levels " + std::to_string(levels));
  }
  if (widths.front() != channels) {
    throw ConfigError(at + "widths: starts with " + std::to_string(widths.front()) + ", not " + at +
                      "channels " + std::to_string(channels));
  }
  for (const int64_t w : widths) {
    if (w < 1) throw ConfigError(at + "widths: every entry must be positive");
  }
}

int64_t ImageNetOptions::receptive_radius() const {
  // Input and output convolutions one pixel each; per level above the bottom, the encoder's
  // and decoder's blocks, the down-sampling (2 x 2, stride 2) and the alignment of the
  // up-sampling, each at that level's pixel size; the bottom level's blocks.
  int64_t r = 2;
  for (int64_t l = 0; l + 1 < levels; ++l) r += (2 * blocks + 2) << l;
  return r + (blocks << (levels - 1));
}

double ImageNetOptions::pixel_flops(int64_t in, int64_t out) const {
  auto conv = [](double cin, double cout, double k, double pixels) {
    return 2.0 * cin * cout * k * k * pixels;
  };
  double flops = conv(static_cast<double>(in + (noise_input ? 1 : 0)), channels, 3, 1) +
                 conv(channels, out, 3, 1);
  for (int64_t l = 0; l < levels; ++l) {
    const double c = static_cast<double>(width(l)), share = 1.0 / static_cast<double>(1 << (2 * l));
    const bool bottom = l + 1 == levels;
    flops += conv(c, c, 3, share) * static_cast<double>(blocks * (bottom ? 1 : 2));
    // down: 2 x 2 stride 2 onto the next level; up: the transposed one back.
    if (!bottom) flops += 2 * conv(c, static_cast<double>(width(l + 1)), 2, share / 4);
  }
  return flops;
}

int64_t round_up(int64_t v, int64_t multiple) { return (v + multiple - 1) / multiple * multiple; }

int64_t auto_image_tile(const ImageTiling& tiling, int64_t height, int64_t width) {
  const int64_t m = tiling.multiple;
  const int64_t hp = round_up(height, m), wp = round_up(width, m);
  if (hp * wp <= tiling.whole * tiling.whole) return std::max(hp, wp);
  const int64_t side = tiling.crop - 2 * round_up(tiling.receptive_radius, m);
  return std::max<int64_t>(side, 256) / m * m;
}

std::vector<ImageTile> image_tiles(const ImageTiling& tiling, int64_t height, int64_t width,
                                   int64_t tile, int64_t* step_out) {
  const int64_t m = tiling.multiple;
  const int64_t halo = round_up(tiling.receptive_radius, m);
  if (tile <= 0) tile = auto_image_tile(tiling, height, width);
  const int64_t step = round_up(tile, m);
  const int64_t hp = round_up(height, m), wp = round_up(width, m);
  if (step_out) *step_out = step;
  std::vector<ImageTile> tiles;
  for (int64_t y0 = 0; y0 < hp; y0 += step) {
    for (int64_t x0 = 0; x0 < wp; x0 += step) {
      tiles.push_back({y0, x0, std::max<int64_t>(0, y0 - halo), std::min(hp, y0 + step + halo),
                       std::max<int64_t>(0, x0 - halo), std::min(wp, x0 + step + halo)});
    }
  }
  return tiles;
}

bool embed_narrow_parameter(const std::string& name, const torch::Tensor& src, torch::Tensor& dst) {
  if (src.dim() != dst.dim()) return false;
  for (int64_t d = 0; d < src.dim(); ++d) {
    if (src.size(d) > dst.size(d)) return false;
  }
  torch::NoGradGuard no_grad;
  auto lead = dst;
  for (int64_t d = 0; d < src.dim(); ++d) lead = lead.narrow(d, 0, src.size(d));
  lead.copy_(src);
  if (src.dim() == 4) {
    // Convolutions hold (out, in, kh, kw); transposed ones ("up") hold (in, out, kh, kw).
    const bool transposed = name.rfind("up", 0) == 0;
    const int64_t out_dim = transposed ? 1 : 0, in_dim = transposed ? 0 : 1;
    const int64_t old_in = src.size(in_dim);
    dst.narrow(out_dim, 0, src.size(out_dim))
        .narrow(in_dim, old_in, dst.size(in_dim) - old_in)
        .zero_();
  }
  return true;
}

namespace {
torch::nn::Conv2d conv3(int64_t in, int64_t out) {
  return torch::nn::Conv2d(torch::nn::Conv2dOptions(in, out, 3).padding(1));
}
}  // namespace

ImageNetImpl::ImageNetImpl(const ImageNetOptions& options, int64_t in, int64_t out)
    : options_(options) {
  options_.validate();
  input_ = register_module("input", conv3(in, options_.channels));
  for (int64_t l = 0; l < options_.levels; ++l) {
    const int64_t c = options_.width(l);
    const bool bottom = l + 1 == options_.levels;
    std::vector<torch::nn::Conv2d> enc, dec;
    for (int64_t b = 0; b < options_.blocks; ++b) {
      const std::string suffix = std::to_string(l) + "_" + std::to_string(b);
      enc.push_back(register_module("enc" + suffix, conv3(c, c)));
      if (!bottom) dec.push_back(register_module("dec" + suffix, conv3(c, c)));
    }
    encoder_.push_back(std::move(enc));
    decoder_.push_back(std::move(dec));
    if (!bottom) {
      const int64_t next = options_.width(l + 1);
      down_.push_back(
          register_module("down" + std::to_string(l),
                          torch::nn::Conv2d(torch::nn::Conv2dOptions(c, next, 2).stride(2))));
      up_.push_back(register_module(
          "up" + std::to_string(l),
          torch::nn::ConvTranspose2d(torch::nn::ConvTranspose2dOptions(next, c, 2).stride(2))));
    }
  }
  output_ = register_module("output", conv3(options_.channels, out));
  torch::NoGradGuard no_grad;
  output_->weight.zero_();
  output_->bias.zero_();
}

void ImageNetImpl::set_precision(torch::Dtype dtype) {
  to(dtype);
  for (auto& up : up_) up->to(torch::kFloat32);
}

std::vector<std::string> ImageNetImpl::start_new_levels(int64_t from_levels) {
  LFNET_CHECK(from_levels >= 1 && from_levels < options_.levels, "start_new_levels: ", from_levels,
              " levels is not fewer than this U-Net's ", options_.levels);
  torch::NoGradGuard no_grad;
  const int64_t l = from_levels - 1;  // the shallow net's bottom level
  const std::string up = "up" + std::to_string(l);
  up_[l]->weight.zero_();
  up_[l]->bias.zero_();
  std::vector<std::string> names = {up + ".weight", up + ".bias"};
  for (size_t b = 0; b < decoder_[l].size(); ++b) {
    auto& conv = decoder_[l][b];
    conv->weight.zero_();
    const int64_t centre = conv->weight.size(2) / 2;
    for (int64_t c = 0; c < conv->weight.size(0); ++c) conv->weight[c][c][centre][centre] = 1;
    conv->bias.zero_();
    const std::string name = "dec" + std::to_string(l) + "_" + std::to_string(b);
    names.push_back(name + ".weight");
    names.push_back(name + ".bias");
  }
  return names;
}

void ImageNetImpl::emulate_precision(torch::Dtype dtype) {
  LFNET_CHECK(dtype == torch::kFloat32 || dtype == torch::kBFloat16, "ImageNet: no emulation of ",
              dtype);
  emulate_bfloat16_ = dtype == torch::kBFloat16;
}

namespace {
// A float32 tensor rounded to the nearest bfloat16 (ties to even), still float32; its gradient
// is the identity (the casts' backward casts back).
torch::Tensor round_bfloat16(const torch::Tensor& t) {
  return t.to(torch::kBFloat16).to(t.scalar_type());
}
}  // namespace

torch::Tensor ImageNetImpl::forward(const torch::Tensor& x) {
  const int64_t m = options_.multiple();
  LFNET_CHECK(x.dim() == 4 && x.size(2) % m == 0 && x.size(3) % m == 0,
              "ImageNet: expected (B, C, H, W) with H and W multiples of ", m, ", got ", x.sizes());
  // In the weights' type (bfloat16 after set_cnn_precision), the output in the input's. Trained
  // for bfloat16 (emulate_precision), float32 weights and every value a bfloat16 run would hold
  // rounded to it (q).
  namespace F = torch::nn::functional;
  const bool emulate = emulate_bfloat16_ && input_->weight.scalar_type() == torch::kFloat32;
  auto q = [emulate](const torch::Tensor& t) { return emulate ? round_bfloat16(t) : t; };
  auto conv = [&](torch::nn::Conv2d& c, const torch::Tensor& in) {
    if (!emulate) return c->forward(in);
    return q(F::conv2d(in, q(c->weight),
                       F::Conv2dFuncOptions()
                           .bias(q(c->bias))
                           .stride(c->options.stride())
                           .padding(c->options.padding())));
  };
  // Every ReLU is in place on a fresh convolution's output, and a skip is let go once added:
  // each level holds one activation fewer, which bounds the peak of a large image.
  auto h = conv(input_, q(x.to(input_->weight.scalar_type()))).relu_();
  std::vector<torch::Tensor> skips;
  const int64_t levels = options_.levels;
  for (int64_t l = 0; l < levels; ++l) {
    for (auto& c : encoder_[l]) h = conv(c, h).relu_();
    if (l + 1 < levels) {
      skips.push_back(h);
      h = conv(down_[l], h).relu_();
    }
  }
  for (int64_t l = levels - 2; l >= 0; --l) {
    const auto type = h.scalar_type();
    h = q(q(up_[l]->forward(h.to(up_[l]->weight.scalar_type())).to(type)).relu_() + skips[l]);
    skips[l] = torch::Tensor();
    for (auto& c : decoder_[l]) h = conv(c, h).relu_();
  }
  return conv(output_, h).to(x.scalar_type());
}

}  // namespace lfnet::nn
