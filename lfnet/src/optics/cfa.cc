#include "lfnet/optics/cfa.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <vector>

#include "lfnet/core/enum_names.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"

namespace lfnet::optics {

namespace {
constexpr const char* kBayerPatterns[] = {"RGGB", "BGGR", "GRBG", "GBRG"};
constexpr int64_t kMaxPeriod = 16;
constexpr EnumName<Demosaic> kDemosaics[] = {{Demosaic::kBilinear, "bilinear"},
                                             {Demosaic::kMalvar, "malvar"}};

// Malvar, He and Cutler's four 5 x 5 filters, in eighths, on the mosaic: a green value at a red
// or blue pixel; a red (blue) value at a green pixel whose row holds red (blue) pixels, and the
// same at one whose column does (the transpose); a red value at a blue pixel and back.
torch::Tensor malvar_filters(const torch::TensorOptions& options) {
  // clang-format off
  const double g_at_rb[25] = {
       0,  0, -1,  0,  0,
       0,  0,  2,  0,  0,
      -1,  2,  4,  2, -1,
       0,  0,  2,  0,  0,
       0,  0, -1,  0,  0};
  const double along_row[25] = {
       0,    0,  0.5,  0,    0,
       0,   -1,  0,   -1,    0,
      -1,    4,  5,    4,   -1,
       0,   -1,  0,   -1,    0,
       0,    0,  0.5,  0,    0};
  const double across[25] = {
       0,    0, -1.5,  0,    0,
       0,    2,  0,    2,    0,
      -1.5,  0,  6,    0, -1.5,
       0,    2,  0,    2,    0,
       0,    0, -1.5,  0,    0};
  // clang-format on
  const auto f = [&](const double* k) {
    return torch::from_blob(const_cast<double*>(k), {5, 5}, torch::kFloat64).clone();
  };
  const auto row = f(along_row);
  return torch::stack({f(g_at_rb), row, row.t(), f(across)}).unsqueeze(1).to(options) / 8.0;
}
}  // namespace

std::string to_string(Demosaic value) { return name_of(value, kDemosaics); }
Demosaic from_string(const std::string& name, Demosaic) { return value_of(name, kDemosaics); }

ColourFilterArray ColourFilterArray::bayer(const std::string& pattern) {
  const bool known = std::find(std::begin(kBayerPatterns), std::end(kBayerPatterns), pattern) !=
                     std::end(kBayerPatterns);
  LFNET_CHECK_AS(ConfigError, known, "unknown Bayer pattern '", pattern,
                 "' (known: RGGB, BGGR, GRBG, GBRG; or a JSON file with a \"response\")");
  ColourFilterArray cfa;
  cfa.pattern_ = pattern;
  cfa.response_ = torch::zeros({3, 2, 2});
  for (int64_t i = 0; i < 4; ++i) {
    const char c = pattern[static_cast<size_t>(i)];
    const int64_t colour = c == 'R' ? 0 : c == 'G' ? 1 : 2;
    cfa.response_[colour][i / 2][i % 2] = 1.0f;
  }
  return cfa;
}

ColourFilterArray ColourFilterArray::from_json(const nlohmann::json& j, const std::string& path) {
  LFNET_CHECK_AS(ConfigError, j.is_object() && (j.contains("pattern") != j.contains("response")),
                 path, ": a colour filter array is {\"pattern\": \"RGGB\"} or {\"response\": ",
                 "[[[r, g, b], ...], ...]}");
  for (auto it = j.begin(); it != j.end(); ++it) {
    LFNET_CHECK_AS(ConfigError, it.key() == "pattern" || it.key() == "response", path, ".",
                   it.key(), ": unknown key (known: pattern, response)");
  }
  if (j.contains("pattern")) {
    LFNET_CHECK_AS(ConfigError, j["pattern"].is_string(), path, ".pattern: expected a string");
    const auto p = j["pattern"].get<std::string>();
    if (p != "custom") return bayer(p);
    LFNET_CHECK_AS(ConfigError, false, path, ".pattern: \"custom\" needs its \"response\"");
  }
  const auto& rows = j["response"];
  const auto n = static_cast<int64_t>(rows.is_array() ? rows.size() : 0);
  LFNET_CHECK_AS(ConfigError, n >= 1 && n <= kMaxPeriod, path,
                 ".response: expected 1 to 16 rows of pixels");
  auto response = torch::zeros({3, n, n});
  for (int64_t y = 0; y < n; ++y) {
    const auto& row = rows[static_cast<size_t>(y)];
    LFNET_CHECK_AS(ConfigError, row.is_array() && static_cast<int64_t>(row.size()) == n, path,
                   ".response[", y, "]: expected ", n, " pixels (the tile is square)");
    for (int64_t x = 0; x < n; ++x) {
      const auto& rgb = row[static_cast<size_t>(x)];
      LFNET_CHECK_AS(ConfigError, rgb.is_array() && rgb.size() == 3, path, ".response[", y, "][", x,
                     "]: expected [r, g, b]");
      double sum = 0;
      for (int64_t c = 0; c < 3; ++c) {
        const auto& v = rgb[static_cast<size_t>(c)];
        // A filter's weight is its transmittance relative to the others: 100 is already absurd,
        // and a float overflows beyond about 3e38.
        LFNET_CHECK_AS(ConfigError, v.is_number() && v.get<double>() >= 0 && v.get<double>() <= 100,
                       path, ".response[", y, "][", x, "][", c,
                       "]: a weight must lie in [0, 100], got ", v.dump());
        response[c][y][x] = v.get<float>();
        sum += v.get<double>();
      }
      LFNET_CHECK_AS(ConfigError, sum > 0, path, ".response[", y, "][", x,
                     "]: a pixel must see some colour");
    }
  }
  ColourFilterArray cfa;
  cfa.pattern_ = "custom";
  cfa.response_ = response;
  return cfa;
}

ColourFilterArray ColourFilterArray::parse(const std::string& text) {
  const bool named = std::find(std::begin(kBayerPatterns), std::end(kBayerPatterns), text) !=
                     std::end(kBayerPatterns);
  if (named) return bayer(text);
  if (is_inline_json(text)) return from_json(read_json_argument(text, "--cfa"), "--cfa");
  try {
    check_regular_input(text);  // before opening: a FIFO would block
  } catch (const IoError& e) {
    throw ConfigError(std::string("--cfa ") + e.what());
  }
  LFNET_CHECK_AS(ConfigError, std::ifstream(text).good(), "--cfa ", text,
                 ": neither a Bayer pattern (RGGB, BGGR, GRBG, GBRG), inline JSON nor a readable "
                 "JSON file");
  return from_json(read_json_file(text), text + ":$");
}

nlohmann::json ColourFilterArray::to_json() const {
  if (pattern_ != "custom") return {{"pattern", pattern_}};
  nlohmann::json rows = nlohmann::json::array();
  const auto r = response_.accessor<float, 3>();
  for (int64_t y = 0; y < period(); ++y) {
    nlohmann::json row = nlohmann::json::array();
    for (int64_t x = 0; x < period(); ++x) row.push_back({r[0][y][x], r[1][y][x], r[2][y][x]});
    rows.push_back(row);
  }
  return {{"response", rows}};
}

bool ColourFilterArray::one_colour_per_pixel() const {
  return ((response_ > 0).sum(0) == 1).all().item<bool>();
}

void ColourFilterArray::check_demosaicable() const {
  LFNET_CHECK_AS(ConfigError, one_colour_per_pixel(),
                 "only colour filter arrays whose pixels each see one colour are demosaiced");
}

torch::Tensor ColourFilterArray::response_image(int64_t height, int64_t width) const {
  const int64_t p = period();
  return response_.repeat({1, (height + p - 1) / p, (width + p - 1) / p})
      .slice(1, 0, height)
      .slice(2, 0, width)
      .contiguous();
}

torch::Tensor mosaic(const torch::Tensor& colour_sensor, const ColourFilterArray& cfa) {
  LFNET_CHECK_AS(ConfigError, colour_sensor.dim() == 4 && colour_sensor.size(0) == 3,
                 "a colour filter array needs the sensor images of three colours (3, N, H, W), "
                 "got ",
                 colour_sensor.sizes());
  const auto r = cfa.response_image(colour_sensor.size(2), colour_sensor.size(3))
                     .to(colour_sensor.scalar_type())
                     .unsqueeze(1);  // (3, 1, H, W)
  return (colour_sensor * r).sum(0, /*keepdim=*/true);
}

torch::Tensor demosaic_malvar(const torch::Tensor& own, const torch::Tensor& response) {
  LFNET_CHECK(own.dim() == 4 && response.dim() == 4 && response.size(1) == 3 &&
                  response.size(0) == own.size(0) && response.size(2) == own.size(2) &&
                  response.size(3) == own.size(3),
              "demosaic_malvar: expected (B, K, h, w) and (B, 3, h, w), got ", own.sizes(), " and ",
              response.sizes());
  const int64_t b = own.size(0), h = own.size(2), w = own.size(3);
  LFNET_CHECK_AS(ConfigError, h >= 3 && w >= 3, "demosaic: an image of ", h, " x ", w,
                 " pixels is too small for malvar demosaicing (3 x 3 at least)");
  const auto is = (response > 0).to(own.options());  // (B, 3, h, w)
  const auto red = is.select(1, 0).unsqueeze(1), green = is.select(1, 1).unsqueeze(1),
             blue = is.select(1, 2).unsqueeze(1);  // (B, 1, h, w)
  // Whether a pixel's row holds red (else blue) pixels: a Bayer pattern alternates them.
  const auto red_row = std::get<0>(red.max(3, /*keepdim=*/true)).expand({b, 1, h, w});
  const auto blue_row = 1 - red_row;
  const auto padded = torch::nn::functional::pad(
      own, torch::nn::functional::PadFuncOptions({2, 2, 2, 2}).mode(torch::kReflect));
  const auto f = filter_channels(padded, malvar_filters(own.options()));  // (B, K, 4, h, w)
  const auto g_at_rb = f.select(2, 0), along_row = f.select(2, 1), along_column = f.select(2, 2),
             across = f.select(2, 3);  // (B, K, h, w)
  const auto at_green = [&](const torch::Tensor& in_row) {
    return in_row * along_row + (1 - in_row) * along_column;
  };
  auto r = red * own + green * at_green(red_row) + blue * across;
  auto g = green * own + (1 - green) * g_at_rb;
  auto bl = blue * own + green * at_green(blue_row) + red * across;
  return torch::stack({r, g, bl}, 1);
}

torch::Tensor filter_channels(const torch::Tensor& images, const torch::Tensor& filters,
                              int64_t padding) {
  LFNET_CHECK(images.dim() == 4 && filters.dim() == 4 && filters.size(1) == 1,
              "filter_channels: expected (B, K, h, w) and (F, 1, kh, kw), got ", images.sizes(),
              " and ", filters.sizes());
  const int64_t k = images.size(1);
  // Output channel c F + j is channel c under filter j.
  const auto out = torch::conv2d(images, filters.repeat({k, 1, 1, 1}), {}, 1, padding, 1, k);
  return out.view({images.size(0), k, filters.size(0), out.size(2), out.size(3)});
}

torch::Tensor demosaic(const torch::Tensor& mosaicked, const ColourFilterArray& cfa,
                       Demosaic method) {
  cfa.check_demosaicable();
  LFNET_CHECK_AS(ConfigError, mosaicked.dim() >= 2, "demosaic: expected (..., H, W), got ",
                 mosaicked.sizes());
  const int64_t h = mosaicked.size(-2), w = mosaicked.size(-1);
  auto shape = mosaicked.sizes().vec();  // (3, ..., H, W)
  shape.insert(shape.begin(), 3);
  if (method == Demosaic::kMalvar) {
    LFNET_CHECK_AS(ConfigError, cfa.pattern() != "custom",
                   "malvar demosaicing needs a Bayer pattern, not a custom colour response");
    const auto response = cfa.response_image(h, w).to(mosaicked.options()).unsqueeze(0);
    return demosaic_malvar(mosaicked.reshape({1, -1, h, w}), response).reshape(shape);
  }
  LFNET_CHECK_AS(ConfigError, h >= 2 && w >= 2, "demosaic: an image of ", h, " x ", w,
                 " pixels is too small");
  const auto options = mosaicked.options();
  const auto response = cfa.response_image(h, w).to(options);
  // Each pixel's value in its own colour: divided by its filter's weight (1 for Bayer).
  const auto images = mosaicked.reshape({1, -1, h, w}) / response.sum(0).view({1, 1, h, w});
  const auto kernel =
      torch::tensor({1.0, 2.0, 1.0, 2.0, 4.0, 2.0, 1.0, 2.0, 1.0}, options).view({1, 1, 3, 3});
  const auto reflect = [](const torch::Tensor& x) {
    return torch::nn::functional::pad(
        x, torch::nn::functional::PadFuncOptions({1, 1, 1, 1}).mode(torch::kReflect));
  };
  std::vector<torch::Tensor> colours;
  for (int64_t c = 0; c < 3; ++c) {
    const auto mask = (response[c] > 0).to(options).view({1, 1, h, w});
    const auto weight = torch::conv2d(reflect(mask), kernel);
    LFNET_CHECK_AS(ConfigError, (weight > 0).all().item<bool>(),
                   "demosaic: the colour filter array leaves pixels with no ", "RGB"[c],
                   " pixel among their eight neighbours");
    const auto mean = filter_channels(reflect(images * mask), kernel).squeeze(2) / weight;
    colours.push_back(torch::where(mask > 0, images, mean));
  }
  return torch::stack(colours).reshape(shape);
}

std::optional<ColourFilterArray> camera_cfa(const nlohmann::json& phi_spec) {
  if (!phi_spec.is_object() || phi_spec.value("name", "") != "calibrated") return std::nullopt;
  const auto params = phi_spec.value("params", nlohmann::json::object());
  if (!params.is_object() || !params.contains("cfa")) return std::nullopt;
  return ColourFilterArray::from_json(params["cfa"], "$.params.cfa");
}

std::optional<ColourFilterArray> resolve_cfa(const std::string& given,
                                             const nlohmann::json& phi_spec) {
  auto own = camera_cfa(phi_spec);
  if (given.empty()) return own;
  auto cfa = ColourFilterArray::parse(given);
  LFNET_CHECK_AS(ConfigError, !own || own->to_json() == cfa.to_json(), "--cfa ", given,
                 " is not the colour filter array of the camera's Phi (", own->to_json().dump(),
                 "): leave --cfa out to use the camera's");
  return cfa;
}

}  // namespace lfnet::optics
