#include "lfnet/io/viewer.h"

#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>

#include <string>

#include "lfnet/core/error.h"
#include "lfnet/io/light_field_io.h"
#include "support/test_support.h"

using namespace lfnet;

namespace {

// The inverse of io::base64, written here independently (RFC 4648 alphabet).
std::string from_base64(const std::string& text) {
  const std::string alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  uint32_t bits = 0;
  int count = 0;
  for (char c : text) {
    if (c == '=') break;
    bits = bits << 6 | static_cast<uint32_t>(alphabet.find(c));
    count += 6;
    if (count >= 8) {
      count -= 8;
      out += static_cast<char>((bits >> count) & 0xff);
    }
  }
  return out;
}

// The JSON the page embeds.
nlohmann::json page_data(const std::string& html) {
  const std::string open = R"(<script id="lfnet-data" type="application/json">)";
  const auto begin = html.find(open) + open.size();
  return nlohmann::json::parse(html.substr(begin, html.find("</script>", begin) - begin));
}

}  // namespace

TEST_CASE("base64 follows RFC 4648", "[io][viewer]") {
  CHECK(io::base64("") == "");
  CHECK(io::base64("f") == "Zg==");
  CHECK(io::base64("fo") == "Zm8=");
  CHECK(io::base64("foo") == "Zm9v");
  CHECK(io::base64("foob") == "Zm9vYg==");
  CHECK(io::base64("foobar") == "Zm9vYmFy");
  std::string bytes;
  for (int i = 0; i < 256; ++i) bytes += static_cast<char>(i);
  CHECK(from_base64(io::base64(bytes)) == bytes);
}

TEST_CASE("the viewer page embeds every view, the truth and the per-view PSNR", "[io][viewer]") {
  const auto lf = test::parallax_light_field(3, 4, 24, 32, 1, -2);
  const auto truth = test::parallax_light_field(3, 4, 24, 32, 1, -1);
  io::ViewerPage page;
  // A folder name may hold anything, "<!--<script" included, which would swallow the page's
  // script (the HTML parser's double-escaped state).
  page.title = "net on </script><b><!--<script>scene";
  page.truth = truth;
  page.record = {{"method", "net"},
                 {"psnr_db", 31.5},
                 {"per_view_psnr_db", std::vector<std::vector<double>>(3, {30, 31, 32, 33})}};
  const std::string html = io::viewer_html(lf, page);
  // One page: the script is inlined and nothing is fetched from elsewhere.
  CHECK(html.find("<!--lfnet:") == std::string::npos);
  CHECK(html.find("window.lfnetViewer") != std::string::npos);
  CHECK(html.find("http://") == std::string::npos);
  CHECK(html.find("https://") == std::string::npos);
  CHECK(html.find("</script><b>") == std::string::npos);  // the title cannot end the script
  CHECK(html.find("<!--<script") == std::string::npos);   // nor swallow it
  const auto data = page_data(html);
  CHECK(data["title"] == page.title);
  CHECK(data["rows"] == 3);
  CHECK(data["cols"] == 4);
  CHECK(data["per_view_psnr_db"][2][3] == 33);
  CHECK_FALSE(data["record"].contains("per_view_psnr_db"));
  CHECK(data["viridis"].size() == 256);  // the page colours with lfnet's one map
  REQUIRE(data["views"].size() == 12);
  REQUIRE(data["truth"].size() == 12);
  // View (u, v) = (1, 2), row-major, decodes back to the light field's view (8-bit).
  test::TempDir dir;
  for (const auto* which : {"views", "truth"}) {
    const std::string uri = data[which][1 * 4 + 2];
    const std::string prefix = "data:image/png;base64,";
    REQUIRE(uri.rfind(prefix, 0) == 0);
    test::write_bytes(dir / "view.png", from_base64(uri.substr(prefix.size())));
    const auto decoded = io::read_image(dir / "view.png");
    const auto& source = std::string(which) == "views" ? lf : truth;
    CHECK(decoded.sizes() == source.view(1, 2).sizes());
    CHECK((decoded - source.view(1, 2)).abs().max().item<float>() <= 0.5f / 255 + 1e-6f);
  }
}

TEST_CASE("views larger than the viewer's limit are shown averaged, and the page says so",
          "[io][viewer]") {
  CHECK(io::viewer_scale(io::kViewerMaxSide, 10) == 1);
  CHECK(io::viewer_scale(10, io::kViewerMaxSide + 1) == 2);
  // The shown side is the whole blocks: 6146 / 3 = 2048 fits, 6147 / 3 = 2049 does not.
  CHECK(io::viewer_scale(3 * io::kViewerMaxSide + 2, 10) == 3);
  CHECK(io::viewer_scale(3 * io::kViewerMaxSide + 3, 10) == 4);
  // 2 x 2 views of 8 x 4100 pixels: shown at 1/3, 2 x 1366 (the last 2 columns dropped).
  const LightField lf(torch::rand({1, 2, 2, 8, 2 * io::kViewerMaxSide + 4}));
  io::ViewerPage page;
  page.max_disparity = 6;
  page.truth = lf;
  const auto data = page_data(io::viewer_html(lf, page));
  CHECK(data["scale"] == 3);
  CHECK(data["height"] == 2);
  CHECK(data["width"] == (2 * io::kViewerMaxSide + 4) / 3);
  CHECK(data["full_width"] == 2 * io::kViewerMaxSide + 4);
  CHECK(data["max_disparity"].get<double>() == Approx(2.0));
  test::TempDir dir;
  for (const auto* which : {"views", "truth"}) {
    const std::string uri = data[which][3];
    test::write_bytes(dir / "view.png",
                      from_base64(uri.substr(std::string("data:image/png;base64,").size())));
    const auto decoded = io::read_image(dir / "view.png");
    CHECK(decoded.sizes() == torch::IntArrayRef({1, 2, (2 * io::kViewerMaxSide + 4) / 3}));
    const auto block = lf.view(1, 1).slice(1, 3, 6).slice(2, 30, 33).mean().item<float>();
    CHECK(decoded[0][1][10].item<float>() == Approx(block).margin(0.5 / 255 + 1e-6));
  }
}

TEST_CASE("the viewer refuses a truth of another shape", "[io][viewer]") {
  io::ViewerPage page;
  page.truth = test::parallax_light_field(3, 3, 24, 32, 1, 1);
  CHECK_THROWS_WITH(io::viewer_html(test::parallax_light_field(3, 4, 24, 32, 1, 1), page),
                    Catch::Contains("differ in shape"));
}

TEST_CASE("without the truth the page has no error map data", "[io][viewer]") {
  const auto data = page_data(io::viewer_html(test::parallax_light_field(2, 2, 16, 16, 1, 1)));
  CHECK(data["truth"].is_null());
  CHECK(data["per_view_psnr_db"].is_null());
  CHECK(data["views"].size() == 4);
}

TEST_CASE("a sequence's page holds its frames' views in order and a frame's rows per frame",
          "[io][viewer]") {
  // Three frames of 2 x 4 views stacked along the rows.
  const auto lf = test::parallax_light_field(6, 4, 12, 16, 1, -2);
  io::ViewerPage page;
  page.frames = 3;
  const auto data = page_data(io::viewer_html(lf, page));
  CHECK(data["frames"] == 3);
  CHECK(data["rows"] == 2);
  CHECK(data["cols"] == 4);
  REQUIRE(data["views"].size() == 24);
  // Frame 2's view (1, 3) is stacked row 2 * 2 + 1: index (2 * 2 + 1) * 4 + 3.
  const std::string uri = data["views"][(2 * 2 + 1) * 4 + 3];
  test::TempDir dir;
  test::write_bytes(dir / "view.png",
                    from_base64(uri.substr(std::string("data:image/png;base64,").size())));
  const auto decoded = io::read_image(dir / "view.png");
  CHECK((decoded - lf.view(5, 3)).abs().max().item<float>() <= 0.5f / 255 + 1e-6f);
  // A still page says one frame; rows that are not whole frames are refused.
  CHECK(page_data(io::viewer_html(lf))["frames"] == 1);
  page.frames = 4;
  CHECK_THROWS_WITH(io::viewer_html(lf, page), Catch::Contains("frames"));
}
