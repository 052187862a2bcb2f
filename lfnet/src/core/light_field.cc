#include "lfnet/core/light_field.h"

#include <limits>
#include <regex>
#include <sstream>

#include "lfnet/core/error.h"
#include "lfnet/core/file_backed.h"

namespace lfnet {

namespace {
// Codes k - 32768 of values k / 65535.
constexpr double kCodeScale = 65535.0;
constexpr double kCodeOffset = 32768.0;
}  // namespace

LightField::LightField(const torch::Tensor& data) {
  LFNET_CHECK(data.defined() && data.dim() == axis::kRank,
              "a light field needs a tensor of shape (C, U, V, H, W)");
  LFNET_CHECK(data.size(axis::kC) == 1 || data.size(axis::kC) == 3,
              "a light field has 1 or 3 channels, got ", data.size(axis::kC));
  data_ = data.to(torch::kFloat32).contiguous();
}

torch::Tensor LightField::view(int64_t u, int64_t v) const {
  LFNET_CHECK(u >= 0 && u < rows() && v >= 0 && v < cols(), "view (", u, ", ", v, ") outside the ",
              rows(), "x", cols(), " grid");
  return data_.select(axis::kU, u).select(axis::kU, v);
}

torch::Tensor encode_codes(const torch::Tensor& values) {
  // floor(65535 v + 1/2) in float32, as OpenImageIO converts float to 16 bits: a written code
  // equals the file's (float32 products fall on exact halves often enough to matter).
  return values.to(torch::kFloat32)
      .clamp(0.0, 1.0)
      .mul_(kCodeScale)
      .add_(0.5)
      .floor_()
      .sub_(kCodeOffset)
      .to(torch::kInt16);
}

torch::Tensor decode_codes(const torch::Tensor& codes) {
  LFNET_CHECK(codes.scalar_type() == torch::kInt16, "decode_codes takes int16 codes, got ",
              codes.scalar_type());
  // k times float32(1 / 65535), as image readers scale 16-bit values: a 16-bit file's views
  // decode to exactly the floats read_image gives.
  return codes.to(torch::kFloat32).add_(kCodeOffset).mul_(static_cast<float>(1.0 / kCodeScale));
}

namespace {
// The codes decoded; a file-backed light field's pages leave memory once read
// (core/file_backed.h), so that going through its views holds one view at a time.
torch::Tensor decoded_once(const torch::Tensor& codes) {
  auto values = decode_codes(codes);
  page_out(codes);
  return values;
}
}  // namespace

LightFieldViews::LightFieldViews(const LightField& lf) : data_(lf.data()) {}

LightFieldViews::LightFieldViews(const torch::Tensor& data) : data_(data) {
  LFNET_CHECK(data.defined() && data.dim() == axis::kRank &&
                  (data.size(axis::kC) == 1 || data.size(axis::kC) == 3),
              "light-field views need a tensor of shape (C, U, V, H, W) with 1 or 3 channels");
  LFNET_CHECK(data.scalar_type() == torch::kFloat32 || data.scalar_type() == torch::kInt16,
              "light-field views are float32 values or int16 codes, not ", data.scalar_type());
}

torch::Tensor LightFieldViews::view(int64_t u, int64_t v) const {
  LFNET_CHECK(u >= 0 && u < rows() && v >= 0 && v < cols(), "view (", u, ", ", v, ") outside the ",
              rows(), "x", cols(), " grid");
  auto view = data_.select(axis::kU, u).select(axis::kU, v);
  return coded() ? decoded_once(view) : view;
}

torch::Tensor LightFieldViews::view_rows(int64_t u, int64_t v, int64_t y0, int64_t y1) const {
  LFNET_CHECK(u >= 0 && u < rows() && v >= 0 && v < cols(), "view (", u, ", ", v, ") outside the ",
              rows(), "x", cols(), " grid");
  LFNET_CHECK(0 <= y0 && y0 < y1 && y1 <= height(), "rows ", y0, "..", y1, " outside a view of ",
              height(), " rows");
  auto rows = data_.select(axis::kU, u).select(axis::kU, v).slice(1, y0, y1);
  return coded() ? decoded_once(rows) : rows;
}

torch::Tensor LightFieldViews::view_bits(int64_t u, int64_t v) const {
  LFNET_CHECK(coded(), "view_bits: the views are not 16-bit codes");
  LFNET_CHECK(u >= 0 && u < rows() && v >= 0 && v < cols(), "view (", u, ", ", v, ") outside the ",
              rows(), "x", cols(), " grid");
  // k - 32768 in two's complement is k with its top bit flipped.
  const auto codes = data_.select(axis::kU, u).select(axis::kU, v);
  auto bits = codes.bitwise_xor(static_cast<int64_t>(std::numeric_limits<int16_t>::min()));
  page_out(codes);
  return bits;
}

LightField LightFieldViews::decode() const {
  return LightField(coded() ? decoded_once(data_) : data_);
}

std::string LightFieldViews::shape_string() const {
  std::ostringstream s;
  s << channels() << "x" << rows() << "x" << cols() << "x" << height() << "x" << width();
  return s.str();
}

LightField LightField::grey() const {
  if (channels() == 1) return *this;
  // Channel by channel: the temporaries are a third of the light field, not all of it.
  auto y = data_[0] * 0.299f;
  y.add_(data_[1] * 0.587f);
  y.add_(data_[2] * 0.114f);
  return LightField(y.unsqueeze(axis::kC));
}

namespace {
// The views [u.begin, u.end) x [v.begin, v.end) of `data` (C, U, V, H, W), checked to fit.
torch::Tensor window_of(const torch::Tensor& data, AngularRange u, AngularRange v) {
  const int64_t rows = data.size(axis::kU), cols = data.size(axis::kV);
  LFNET_CHECK(u.begin >= 0 && u.end <= rows && u.size() > 0 && v.begin >= 0 && v.end <= cols &&
                  v.size() > 0,
              "angular window rows ", u.begin + 1, ":", u.end, ", columns ", v.begin + 1, ":",
              v.end, " (1-based) does not fit the ", rows, "x", cols, " grid");
  return data.slice(axis::kU, u.begin, u.end).slice(axis::kV, v.begin, v.end);
}
}  // namespace

LightField LightField::window(AngularRange u, AngularRange v) const {
  return LightField(window_of(data_, u, v));
}

LightFieldViews LightFieldViews::window(AngularRange u, AngularRange v) const {
  return LightFieldViews(window_of(data_, u, v));
}

LightField LightField::central(int64_t n) const {
  LFNET_CHECK(n <= rows() && n <= cols(), "cannot take the central ", n, "x", n, " views of a ",
              rows(), "x", cols(), " grid");
  int64_t u0 = central_start(rows(), n);
  int64_t v0 = central_start(cols(), n);
  return window({u0, u0 + n}, {v0, v0 + n});
}

LightField LightField::angular_mean() const {
  auto mean = data_.mean({axis::kU, axis::kV}, /*keepdim=*/true);
  return LightField(mean.expand_as(data_).clone());
}

std::string LightField::shape_string() const {
  if (!defined()) return "(empty)";
  std::ostringstream out;
  out << channels() << "x" << rows() << "x" << cols() << "x" << height() << "x" << width();
  return out.str();
}

int64_t central_start(int64_t total, int64_t n) {
  LFNET_CHECK(n >= 1 && n <= total, "cannot take ", n, " central views of ", total);
  // The Lytro protocol of the paper takes views 6..10 (1-based) of a 14 x 14 grid, one view
  // after the floor of the centre; every other grid uses the floor.
  if (total == 14 && n == 5) return 5;
  return (total - n) / 2;
}

std::pair<AngularRange, AngularRange> parse_views(const std::string& text) {
  static const std::regex kPattern(R"(^\s*(\d+):(\d+)\s*,\s*(\d+):(\d+)\s*$)");
  std::smatch m;
  if (!std::regex_match(text, m, kPattern)) {
    throw ConfigError("views '" + text +
                      "' is not of the form R0:R1,C0:C1 (1-based, inclusive), e.g. 3:7,3:7");
  }
  for (size_t i = 1; i <= 4; ++i) {
    // A view index is small; more digits than that would overflow stoll.
    if (m[i].length() > 6) {
      throw ConfigError("views '" + text + "': view index " + m[i].str() +
                        " is far beyond any light field's grid");
    }
  }
  auto r0 = std::stoll(m[1]), r1 = std::stoll(m[2]), c0 = std::stoll(m[3]), c1 = std::stoll(m[4]);
  if (r0 < 1 || c0 < 1 || r1 < r0 || c1 < c0) {
    throw ConfigError("views '" + text + "': indices are 1-based and R0 <= R1, C0 <= C1");
  }
  return {AngularRange{r0 - 1, r1}, AngularRange{c0 - 1, c1}};
}

}  // namespace lfnet
