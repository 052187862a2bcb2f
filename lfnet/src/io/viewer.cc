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
std::vector<std::string> view_uris(const LightFieldViews& lf, int64_t f) {
  const int64_t cols = lf.cols();
  std::vector<std::string> encoded(static_cast<size_t>(lf.rows() * cols));
  parallel_chunks(lf.rows() * cols, 1, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      auto view = lf.view(i / cols, i % cols);
      if (f > 1) view = torch::avg_pool2d(view.unsqueeze(1), {f, f}, {f, f}).squeeze(1);
      encoded[static_cast<size_t>(i)] = data_uri(view);
    }
  });
  return encoded;
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

namespace {

// Where the data's lists of views stand in its JSON text until they are spliced in.
constexpr std::string_view kViewsMarker = "lfnet:views-of-the-page";
constexpr std::string_view kTruthMarker = "lfnet:truth-of-the-page";

// The page in pieces: the template around the data, and the data's JSON text with each list of
// views spliced in where its marker stands. The views (tens of MB for large light fields) are
// held once, as encoded, and the page is never made whole to be written.
struct PagePieces {
  std::string head, data, tail;  // the template before the data, the data's text, the rest
  std::vector<std::string> views, truth;

  std::vector<std::string_view> pieces() const {
    std::vector<std::string_view> out{head};
    std::string_view rest = data;
    while (!rest.empty()) {
      // The next marker (in quotes, as the JSON text holds it), if any.
      size_t at = std::string_view::npos;
      const std::vector<std::string>* list = nullptr;
      for (const auto& [marker, uris] :
           {std::pair{kViewsMarker, &views}, std::pair{kTruthMarker, &truth}}) {
        const auto found = rest.find("\"" + std::string(marker) + "\"");
        if (found < at) {
          at = found;
          list = uris;
        }
      }
      if (list == nullptr) break;
      out.push_back(rest.substr(0, at));
      out.emplace_back("[");
      for (size_t i = 0; i < list->size(); ++i) {
        if (i > 0) out.emplace_back(",");
        out.emplace_back("\"");
        out.emplace_back((*list)[i]);  // base64 data URIs: nothing to escape
        out.emplace_back("\"");
      }
      out.emplace_back("]");
      rest.remove_prefix(at + kViewsMarker.size() + 2);  // both markers are as long
    }
    out.push_back(rest);
    out.emplace_back(tail);
    return out;
  }
};

PagePieces page_pieces(const LightFieldViews& lf, const ViewerPage& page) {
  static_assert(kViewsMarker.size() == kTruthMarker.size());
  // Views larger than kViewerMaxSide are shown averaged over f x f pixels: the page stays a size
  // a browser opens, and its disparities are in the pixels shown.
  const int64_t f = viewer_scale(lf.height(), lf.width());
  LFNET_CHECK(page.frames >= 1 && lf.rows() % page.frames == 0, "the viewer's ", lf.rows(),
              " stacked rows are not ", page.frames, " frames");
  PagePieces p;
  nlohmann::json data = {{"title", page.title.empty() ? "light field" : page.title},
                         {"frames", page.frames},
                         {"rows", lf.rows() / page.frames},
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
                         {"views", kViewsMarker},
                         {"truth", nullptr},
                         {"per_view_psnr_db", nullptr}};
  p.views = view_uris(lf, f);
  if (page.truth) {
    const auto& t = *page.truth;
    LFNET_CHECK(t.rows() == lf.rows() && t.cols() == lf.cols() && t.height() == lf.height() &&
                    t.width() == lf.width(),
                "the viewer's truth (", t.shape_string(), ") and light field (", lf.shape_string(),
                ") differ in shape");
    data["truth"] = kTruthMarker;
    p.truth = view_uris(t, f);
    if (page.record.contains("per_view_psnr_db"))
      data["per_view_psnr_db"] = page.record["per_view_psnr_db"];
  }
  data["record"].erase("per_view_psnr_db");
  p.data = script_safe(data.dump());
  // The markers stand once each: a title or record holding one would be spliced too.
  for (const auto marker : {kViewsMarker, kTruthMarker}) {
    const std::string quoted = "\"" + std::string(marker) + "\"";
    const auto first = p.data.find(quoted);
    LFNET_CHECK(first == std::string::npos || p.data.find(quoted, first + 1) == std::string::npos,
                "the viewer's title or record holds \"", marker, "\"");
  }
  std::string html(kViewerHtml);
  fill(html, "<!--lfnet:script-->", kViewerJs);  // first: the data may hold any text
  constexpr std::string_view kDataMarker = "<!--lfnet:data-->";
  const auto at = html.find(kDataMarker);
  LFNET_CHECK(at != std::string::npos, "viewer template lacks ", kDataMarker);
  p.head = html.substr(0, at);
  p.tail = html.substr(at + kDataMarker.size());
  return p;
}

}  // namespace

std::string viewer_html(const LightFieldViews& lf, const ViewerPage& page) {
  const auto p = page_pieces(lf, page);
  std::string html;
  for (const auto piece : p.pieces()) html += piece;
  return html;
}

void write_viewer(const LightFieldViews& lf, const std::string& path, const ViewerPage& page) {
  const auto p = page_pieces(lf, page);
  write_pieces_file(path, p.pieces());
}

}  // namespace lfnet::io
