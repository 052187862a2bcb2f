#include "lfnet/io/viewer.h"

#include <algorithm>
#include <string_view>
#include <vector>

#include "lfnet/core/colour_map.h"
#include "lfnet/core/error.h"
#include "lfnet/core/output.h"
#include "lfnet/core/parallel.h"
#include "lfnet/io/light_field_io.h"
#include "viewer_assets.h"

namespace lfnet::io {

namespace {

std::string data_uri(const torch::Tensor& view) {
  return "data:image/png;base64," + base64(encode_png(view));
}

// The views averaged over f x f pixels (downscale_views), as PNG data URIs: one view at a time
// is downscaled and encoded, on LibTorch's thread count, so no downscaled copy of the whole
// light field is held.
nlohmann::json view_uris(const LightFieldViews& lf, int64_t f) {
  const int64_t cols = lf.cols();
  std::vector<std::string> encoded(static_cast<size_t>(lf.rows() * cols));
  parallel_chunks(lf.rows() * cols, 1, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      auto view = lf.view(i / cols, i % cols);
      if (f > 1) view = torch::avg_pool2d(view.unsqueeze(1), {f, f}, {f, f}).squeeze(1);
      encoded[static_cast<size_t>(i)] = data_uri(view);
    }
  });
  auto uris = nlohmann::json::array();
  for (auto& uri : encoded) uris.push_back(std::move(uri));
  return uris;
}

// Replaces the one `marker` of `text` with `value`.
void fill(std::string& text, std::string_view marker, const std::string& value) {
  const auto at = text.find(marker);
  LFNET_CHECK(at != std::string::npos, "viewer template lacks ", marker);
  text.replace(at, marker.size(), value);
}

// JSON inside <script>: "</" would end the element early, and "<!--" followed by "<script" would
// swallow the rest of the page (the HTML parser's double-escaped script state). JSON holds "<"
// only inside strings, where "\u003c" reads as the same character.
std::string script_safe(const std::string& json) {
  std::string out;
  out.reserve(json.size());
  for (const char c : json) {
    if (c == '<') {
      out += "\\u003c";
    } else {
      out += c;
    }
  }
  return out;
}

}  // namespace

std::string base64(const std::string& bytes) {
  static constexpr char kAlphabet[] =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t n = static_cast<uint8_t>(bytes[i]) << 16 |
                       static_cast<uint8_t>(bytes[i + 1]) << 8 | static_cast<uint8_t>(bytes[i + 2]);
    for (int shift : {18, 12, 6, 0}) out += kAlphabet[(n >> shift) & 63];
  }
  if (i < bytes.size()) {
    const bool two = i + 1 < bytes.size();
    const uint32_t n =
        static_cast<uint8_t>(bytes[i]) << 16 | (two ? static_cast<uint8_t>(bytes[i + 1]) << 8 : 0);
    out += kAlphabet[(n >> 18) & 63];
    out += kAlphabet[(n >> 12) & 63];
    out += two ? kAlphabet[(n >> 6) & 63] : '=';
    out += '=';
  }
  return out;
}

int64_t viewer_scale(int64_t height, int64_t width) {
  int64_t f = 1;
  while (std::max(height, width) / f > kViewerMaxSide) ++f;
  return f;
}

std::string viewer_html(const LightFieldViews& lf, const ViewerPage& page) {
  // Views larger than kViewerMaxSide are shown averaged over f x f pixels: the page stays a size
  // a browser opens, and its disparities are in the pixels shown.
  const int64_t f = viewer_scale(lf.height(), lf.width());
  nlohmann::json data = {{"title", page.title.empty() ? "light field" : page.title},
                         {"rows", lf.rows()},
                         {"cols", lf.cols()},
                         {"height", lf.height() / f},  // as downscale_views drops the rest
                         {"width", lf.width() / f},
                         {"scale", f},
                         {"full_height", lf.height()},
                         {"full_width", lf.width()},
                         {"channels", lf.channels()},
                         {"max_disparity", page.max_disparity / static_cast<double>(f)},
                         {"record", page.record},
                         {"viridis", viridis_table()},
                         {"views", view_uris(lf, f)},
                         {"truth", nullptr},
                         {"per_view_psnr_db", nullptr}};
  if (page.truth) {
    const auto& t = *page.truth;
    LFNET_CHECK(t.rows() == lf.rows() && t.cols() == lf.cols() && t.height() == lf.height() &&
                    t.width() == lf.width(),
                "the viewer's truth (", t.shape_string(), ") and light field (", lf.shape_string(),
                ") differ in shape");
    data["truth"] = view_uris(t, f);
    if (page.record.contains("per_view_psnr_db"))
      data["per_view_psnr_db"] = page.record["per_view_psnr_db"];
  }
  data["record"].erase("per_view_psnr_db");
  std::string html(kViewerHtml);
  fill(html, "<!--lfnet:script-->", kViewerJs);  // first: the data may hold any text
  // The views make the data tens of MB for large light fields: each form is freed as soon as
  // the next is made, so at most two are held at once.
  std::string text = data.dump();
  data = nullptr;
  text = script_safe(text);
  fill(html, "<!--lfnet:data-->", text);
  return html;
}

void write_viewer(const LightFieldViews& lf, const std::string& path, const ViewerPage& page) {
  write_text_file(path, viewer_html(lf, page));
}

}  // namespace lfnet::io
