// The offline light-field viewer: one self-contained HTML page (docs/viewer.md).
#pragma once

#include <nlohmann/json.hpp>

#include <optional>
#include <string>

#include "lfnet/core/light_field.h"

namespace lfnet::io {

// What the page shows beside the light field.
struct ViewerPage {
  std::string title;                     // the heading, e.g. "net on hci_antinous"
  std::optional<LightFieldViews> truth;  // of the same shape: error map and "show truth"
  // An evaluate or reconstruct record: method, Phi, PSNR, SSIM and seconds are listed, and
  // per_view_psnr_db fills the per-view table.
  nlohmann::json record = nlohmann::json::object();
  double max_disparity = 4;  // the refocus slider spans +-max(4, this) px per view step
  // T: the light field is T frames of a sequence stacked along the angular rows (frame t's rows
  // t U to (t + 1) U - 1), and the page has a time slider beside the view pad.
  int64_t frames = 1;
};

// The longest side of a view the page shows at full resolution; larger views are averaged over
// f x f pixels, f = viewer_scale(H, W), the smallest factor that brings them within it.
inline constexpr int64_t kViewerMaxSide = 2048;
int64_t viewer_scale(int64_t height, int64_t width);

// The page as text: viewer.html with viewer.js and the views (8-bit PNG data URIs, row-major)
// embedded, so it opens from a file in any browser without a network. The page data says the
// views' shown size (height, width), their full size and the factor between (scale).
std::string viewer_html(const LightFieldViews& lf, const ViewerPage& page = {});

// Writes viewer_html to `path` (usually DIR/index.html) through a temporary file.
void write_viewer(const LightFieldViews& lf, const std::string& path, const ViewerPage& page = {});

// Base64 (RFC 4648, with padding) of bytes.
std::string base64(const std::string& bytes);

}  // namespace lfnet::io
