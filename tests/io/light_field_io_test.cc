#include "lfnet/io/light_field_io.h"

#include <catch2/catch.hpp>

#include <cstdio>
#include <filesystem>
#include <fstream>

#include "lfnet/core/error.h"
#include "lfnet/core/parallax.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using lfnet::LightField;
namespace io = lfnet::io;

namespace {
// Writes the views of `lf` under the file names `name(u, v)` (0-based u, v).
template <typename Namer>
void write_views(const LightField& lf, const std::string& dir, Namer name, int bits = 16) {
  fs::create_directories(dir);
  for (int64_t u = 0; u < lf.rows(); ++u) {
    for (int64_t v = 0; v < lf.cols(); ++v) {
      io::write_image((fs::path(dir) / name(u, v)).string(), lf.view(u, v), bits);
    }
  }
}

std::string fmt(const char* pattern, long long a, long long b = 0) {
  char buf[128];
  std::snprintf(buf, sizeof buf, pattern, a, b);
  return buf;
}
}  // namespace

TEST_CASE("light fields round-trip through PNG, TIFF and EXR", "[io]") {
  lfnet::test::TempDir tmp;
  LightField lf(torch::rand({3, 2, 3, 7, 11}));
  SECTION("16-bit PNG") {
    io::write_light_field(lf, tmp / "png16", {"png", 16});
    auto back = io::read_light_field(tmp / "png16");
    lfnet::test::require_close(back.data(), lf.data(), 0.5 / 65535 + 1e-7);
  }
  SECTION("8-bit PNG") {
    io::write_light_field(lf, tmp / "png8", {"png", 8});
    auto back = io::read_light_field(tmp / "png8");
    lfnet::test::require_close(back.data(), lf.data(), 0.5 / 255 + 1e-7);
    CHECK_FALSE(torch::allclose(back.data(), lf.data(), 0, 1e-4));  // really quantised
  }
  SECTION("float TIFF and EXR are exact") {
    io::write_light_field(lf, tmp / "tif", {"tif", 32});
    REQUIRE(torch::equal(io::read_light_field(tmp / "tif").data(), lf.data()));
    io::write_light_field(lf, tmp / "exr", {"exr", 32});
    REQUIRE(torch::equal(io::read_light_field(tmp / "exr").data(), lf.data()));
  }
}

TEST_CASE("every naming scheme is recognised with its grid", "[io]") {
  lfnet::test::TempDir tmp;
  LightField lf(torch::rand({1, 3, 3, 5, 6}));
  struct Case {
    std::string name;
    std::function<std::string(int64_t, int64_t)> namer;
    io::NamingScheme scheme;
  };
  std::vector<Case> cases = {
      {"hci", [](int64_t u, int64_t v) { return fmt("input_Cam%03lld.png", 3 * u + v); },
       io::NamingScheme::kHciCam},
      {"rowcol", [](int64_t u, int64_t v) { return fmt("lf_%lld_%lld.png", u + 1, v + 1); },
       io::NamingScheme::kRowCol},
      {"tm", [](int64_t u, int64_t v) { return fmt("TM_%02lld_%02lld.png", u + 1, v + 1); },
       io::NamingScheme::kTmRowCol},
      // The MIT archive numbers its files from the bottom row of views (camera Y points up).
      {"mit", [](int64_t u, int64_t v) { return fmt("dragons-%lld.png", 3 * (2 - u) + v + 1); },
       io::NamingScheme::kMitIndex},
  };
  for (const auto& c : cases) {
    INFO(c.name);
    write_views(lf, tmp / c.name, c.namer);
    // Unrelated files are ignored.
    std::ofstream(tmp / c.name + "/README.txt") << "notes";
    auto layout = io::scan_folder(tmp / c.name);
    CHECK(layout.scheme == c.scheme);
    CHECK(layout.rows == 3);
    CHECK(layout.cols == 3);
    auto back = io::read_light_field(tmp / c.name);
    // View (u, v) lands at (u, v): compare every view, not just the shape.
    lfnet::test::require_close(back.data(), lf.data(), 0.5 / 65535 + 1e-7);
  }
}

TEST_CASE("after loading, horizontal and vertical parallax agree in sign for every scheme",
          "[io][parallax]") {
  lfnet::test::TempDir tmp;
  // Known disparities +2 and -1 px per view step, in lfnet's orientation (u down, v right).
  const auto lf = lfnet::test::parallax_light_field(5, 5, 128, 160, 2, -1, 7);
  REQUIRE(lfnet::check_parallax(lf).verdict == lfnet::ParallaxVerdict::kAgree);
  // Each scheme's files as its own camera writes them: the MIT archive's 01 is the bottom-left
  // camera (X = -2.5, Y = -2.5 cm in its README), 05 bottom-right, 21 top-left.
  const std::vector<std::pair<std::string, std::function<std::string(int64_t, int64_t)>>> schemes =
      {
          {"hci", [](int64_t u, int64_t v) { return fmt("input_Cam%03lld.png", 5 * u + v); }},
          {"rowcol", [](int64_t u, int64_t v) { return fmt("lf_%lld_%lld.png", u + 1, v + 1); }},
          {"tm", [](int64_t u, int64_t v) { return fmt("TM_%02lld_%02lld.png", u + 1, v + 1); }},
          {"name",
           [](int64_t u, int64_t v) { return fmt("2067_%02lld_%02lld.png", u + 1, v + 1); }},
          {"mit",
           [](int64_t u, int64_t v) { return fmt("scene-%02lld.png", 5 * (4 - u) + v + 1); }},
      };
  for (const auto& [name, namer] : schemes) {
    INFO(name);
    write_views(lf, tmp / name, namer);
    const auto back = io::read_light_field(tmp / name);
    const auto check = lfnet::check_parallax(back);
    INFO(check.summary());
    CHECK(check.verdict == lfnet::ParallaxVerdict::kAgree);
    CHECK(check.correlation > 0.9);
  }
  // The MIT files read top row first (the old reading) would disagree: the check sees it.
  const auto upside_down = lfnet::reorient(io::read_light_field(tmp / "mit"),
                                           lfnet::AngularOrientation::parse("flip-u", "test"));
  CHECK(lfnet::check_parallax(upside_down).verdict == lfnet::ParallaxVerdict::kDisagree);
}

TEST_CASE("RGBA views are read as RGB", "[io]") {
  lfnet::test::TempDir tmp;
  auto rgba = torch::rand({4, 5, 6});
  io::write_image(tmp / "lf_1_1.png", rgba, 16);
  auto img = io::read_image(tmp / "lf_1_1.png");
  REQUIRE(img.size(0) == 3);
  lfnet::test::require_close(img, rgba.slice(0, 0, 3), 0.5 / 65535 + 1e-7);
}

TEST_CASE("broken folders give errors that name the file", "[io]") {
  lfnet::test::TempDir tmp;
  LightField lf(torch::rand({1, 2, 2, 5, 6}));
  auto namer = [](int64_t u, int64_t v) { return fmt("lf_%lld_%lld.png", u + 1, v + 1); };

  SECTION("missing view") {
    write_views(lf, tmp / "gap", namer);
    fs::remove(tmp / "gap/lf_2_1.png");
    CHECK_THROWS_WITH(io::read_light_field(tmp / "gap"), Catch::Contains("lf_2_1.png"));
  }
  SECTION("views of different sizes") {
    write_views(lf, tmp / "sizes", namer);
    io::write_image(tmp / "sizes/lf_1_2.png", torch::rand({1, 4, 6}));
    CHECK_THROWS_WITH(io::read_light_field(tmp / "sizes"), Catch::Contains("lf_1_2.png"));
  }
  SECTION("truncated file") {
    write_views(lf, tmp / "trunc", namer);
    fs::resize_file(tmp / "trunc/lf_2_2.png", 40);
    CHECK_THROWS_WITH(io::read_light_field(tmp / "trunc"), Catch::Contains("lf_2_2.png"));
  }
  SECTION("gap in an index scheme") {
    write_views(lf, tmp / "hci",
                [](int64_t u, int64_t v) { return fmt("input_Cam%03lld.png", 2 * u + v); });
    fs::remove(tmp / "hci/input_Cam001.png");
    CHECK_THROWS_WITH(io::read_light_field(tmp / "hci"), Catch::Contains("numbered 1"));
  }
  SECTION("no views and no folder") {
    fs::create_directories(tmp / "empty");
    CHECK_THROWS_AS(io::read_light_field(tmp / "empty"), lfnet::IoError);
    CHECK_THROWS_WITH(io::read_light_field(tmp / "nope"), Catch::Contains("nope"));
  }
  SECTION("mixed schemes") {
    write_views(lf, tmp / "mixed", namer);
    io::write_image(tmp / "mixed/TM_01_01.png", lf.view(0, 0));
    CHECK_THROWS_WITH(io::read_light_field(tmp / "mixed"), Catch::Contains("mixes"));
  }
}

TEST_CASE("PFM round-trips with rows top to bottom", "[io]") {
  lfnet::test::TempDir tmp;
  auto img = torch::rand({1, 4, 7});
  io::write_pfm(tmp / "d.pfm", img);
  auto back = io::read_pfm(tmp / "d.pfm");
  REQUIRE(torch::equal(back, img));
  // The file stores the bottom row first.
  std::ifstream in(tmp / "d.pfm", std::ios::binary);
  std::string magic;
  int w, h;
  double scale;
  in >> magic >> w >> h >> scale;
  in.get();
  float first = 0;
  in.read(reinterpret_cast<char*>(&first), sizeof first);
  CHECK(first == img[0][3][0].item<float>());
  CHECK(scale < 0);
  // Truncated PFM is an error.
  fs::resize_file(tmp / "d.pfm", 30);
  CHECK_THROWS_WITH(io::read_pfm(tmp / "d.pfm"), Catch::Contains("truncated"));
}

TEST_CASE("grid images and EPIs place the views", "[io]") {
  LightField lf(torch::rand({1, 3, 5, 8, 10}));
  auto grid = io::grid_image(lf, 2);
  CHECK(grid.size(1) == 3 * 10 - 2);
  CHECK(grid.size(2) == 5 * 12 - 2);
  lfnet::test::require_close(grid.slice(1, 10, 18).slice(2, 24, 34), lf.view(1, 2), 0.0);
  auto epi = io::horizontal_epi(lf, 3, 2);
  REQUIRE(epi.sizes() == torch::IntArrayRef({1, 10, 10}));
  lfnet::test::require_close(epi[0][2 * 4 + 1], lf.data()[0][1][4][3], 0.0);
  auto vepi = io::vertical_epi(lf, 6, 1);
  REQUIRE(vepi.sizes() == torch::IntArrayRef({1, 3, 8}));
  lfnet::test::require_close(vepi[0][2], lf.data()[0][2][2].select(1, 6), 0.0);
}

TEST_CASE("grid.png holds the grid of the preview in 8 bits", "[io]") {
  lfnet::test::TempDir tmp;
  torch::manual_seed(3);
  for (const int64_t c : {1, 3}) {
    LightField lf(torch::rand({c, 3, 4, 9, 7}));
    const lfnet::LightFieldViews coded(lfnet::encode_codes(lf.data()));
    const auto dir = tmp / ("c" + std::to_string(c));
    io::write_previews(coded, dir);
    const auto grid = io::read_image(fs::path(dir) / "grid.png");
    const auto want = io::grid_image(io::preview_light_field(coded));
    REQUIRE(grid.sizes() == want.sizes());
    CHECK(torch::equal((grid * 255).round(), (want * 255).round()));
    CHECK(fs::exists(fs::path(dir) / "epi_h.png"));
  }
}

TEST_CASE("a preview grid wider than its limit shows block averages of the views", "[io]") {
  LightField lf(torch::rand({1, 2, 3, 12, 20}));
  // 3 x (20 + 2) - 2 = 64 columns fit 64: the light field itself.
  CHECK(io::preview_light_field(lf, 64).data().data_ptr() == lf.data().data_ptr());
  // 63 do not: f = 2 gives 3 x (10 + 2) - 2 = 34 columns and 2 x (6 + 2) - 2 = 14 rows.
  const auto small = io::preview_light_field(lf, 63);
  REQUIRE(small.data().sizes() == torch::IntArrayRef({1, 2, 3, 6, 10}));
  const auto block = lf.view(1, 2).slice(1, 4, 6).slice(2, 8, 10).mean().item<float>();
  CHECK(small.view(1, 2)[0][2][4].item<float>() == Approx(block).epsilon(1e-6));
  // 30 columns need f = 3 for the width (3 x (6 + 2) - 2 = 22), whatever the rows allow.
  CHECK(io::preview_light_field(lf, 30).width() == 6);
  // A factor that does not divide the views drops the last rows and columns.
  CHECK(io::downscale_views(lf, 7).data().sizes() == torch::IntArrayRef({1, 2, 3, 1, 2}));
  CHECK_THROWS(io::downscale_views(lf, 13));
}

TEST_CASE("writing never leaves partial files behind", "[io]") {
  lfnet::test::TempDir tmp;
  CHECK_THROWS_AS(io::write_image(tmp / "x.unknownformat", torch::rand({1, 4, 4})), lfnet::IoError);
  CHECK_THROWS_AS(io::write_image(tmp / "missing_dir/x.png", torch::rand({1, 4, 4})),
                  lfnet::IoError);
  int files = 0;
  for (auto& e : fs::recursive_directory_iterator(tmp.path())) files += e.is_regular_file();
  CHECK(files == 0);
}

TEST_CASE("<name>_RR_CC folders: either separator, 0- or 1-based, any digit count", "[io]") {
  lfnet::test::TempDir tmp;
  LightField lf(torch::rand({1, 3, 4, 5, 6}));
  struct Case {
    std::string name;
    std::function<std::string(int64_t, int64_t)> namer;
  };
  const std::vector<Case> cases = {
      {"lytro", [](int64_t u, int64_t v) { return fmt("2067_%02lld_%02lld.png", u + 1, v + 1); }},
      {"zero", [](int64_t u, int64_t v) { return fmt("scene_%lld_%lld.png", u, v); }},
      {"dash", [](int64_t u, int64_t v) { return fmt("my-lf-%03lld-%03lld.tif", u + 1, v + 1); }},
  };
  for (const auto& c : cases) {
    INFO(c.name);
    write_views(lf, tmp / c.name, c.namer);
    const auto layout = io::scan_folder(tmp / c.name);
    CHECK(layout.scheme == io::NamingScheme::kNameRowCol);
    CHECK(layout.rows == 3);
    CHECK(layout.cols == 4);
    lfnet::test::require_close(io::read_light_field(tmp / c.name).data(), lf.data(),
                               0.5 / 65535 + 1e-7);
  }
  // A gap names the missing file in the folder's own spelling; two prefixes are two fields.
  fs::remove(tmp / "lytro/2067_02_03.png");
  CHECK_THROWS_WITH(io::scan_folder(tmp / "lytro"), Catch::Contains("2067_02_03.png"));
  write_views(lf, tmp / "two", [](int64_t u, int64_t v) { return fmt("a_%lld_%lld.png", u, v); });
  io::write_image(tmp / "two/b_0_0.png", lf.view(0, 0));
  CHECK_THROWS_WITH(io::scan_folder(tmp / "two"), Catch::Contains("two light fields"));
  // A grid starting at 2 is not guessed at.
  write_views(lf, tmp / "late",
              [](int64_t u, int64_t v) { return fmt("x_%lld_%lld.png", u + 2, v + 2); });
  CHECK_THROWS_WITH(io::scan_folder(tmp / "late"), Catch::Contains("0- or 1-based"));
}

TEST_CASE("layout patterns read any naming: row and column fields, or an index and a width",
          "[io]") {
  lfnet::test::TempDir tmp;
  LightField lf(torch::rand({1, 3, 4, 5, 6}));
  struct Case {
    std::string name, layout;
    std::function<std::string(int64_t, int64_t)> namer;
  };
  const std::vector<Case> cases = {
      // Column first in the name, 0-based, other text around the fields.
      {"colfirst", "cam{col}x{row}_rect.png",
       [](int64_t u, int64_t v) { return fmt("cam%lldx%lld_rect.png", v, u); }},
      // Row-major index, 1-based, three digits, a wildcard for a varying suffix.
      {"rowmajor", "img{index}*.png:cols=4",
       [](int64_t u, int64_t v) { return fmt("img%03lld_v2.png", u * 4 + v + 1); }},
      // Column-major index (views numbered down each column), 0-based.
      {"colmajor", "frame.{index}.tif:cols=4:col-major",
       [](int64_t u, int64_t v) { return fmt("frame.%lld.tif", v * 3 + u); }},
  };
  for (const auto& c : cases) {
    INFO(c.name);
    write_views(lf, tmp / c.name, c.namer);
    const auto layout = io::scan_folder(tmp / c.name, c.layout);
    CHECK(layout.scheme == io::NamingScheme::kCustom);
    CHECK(layout.rows == 3);
    CHECK(layout.cols == 4);
    lfnet::test::require_close(io::read_light_field(tmp / c.name, 0, c.layout).data(), lf.data(),
                               0.5 / 65535 + 1e-7);
  }
  // Without the pattern, the column-first folder is not recognised; with it, a gap is named.
  CHECK_THROWS_AS(io::scan_folder(tmp / "colfirst"), lfnet::IoError);
  fs::remove(tmp / "rowmajor/img006_v2.png");  // row 2, column 2 (1-based)
  CHECK_THROWS_WITH(io::scan_folder(tmp / "rowmajor", "img{index}*.png:cols=4"),
                    Catch::Contains("row 2, column 2"));
  CHECK_THROWS_WITH(io::scan_folder(tmp / "colmajor", "nothing{index}.png:cols=4"),
                    Catch::Contains("matches --layout"));
  // Malformed patterns: each a ConfigError that says what is wrong.
  CHECK_THROWS_WITH(io::parse_layout("img{index}.png"), Catch::Contains("cols=9"));
  CHECK_THROWS_WITH(io::parse_layout("img{row}.png"), Catch::Contains("{row} and {col}"));
  CHECK_THROWS_WITH(io::parse_layout("a/{row}_{col}.png"), Catch::Contains("'/'"));
  CHECK_THROWS_WITH(io::parse_layout("{row}_{col}.png:cols=4"), Catch::Contains("{index}"));
  CHECK_THROWS_WITH(io::parse_layout("{index}.png:cols=4:sideways"),
                    Catch::Contains("unknown option"));
}

TEST_CASE("16-bit codes write the files their float32 values write, byte for byte", "[io]") {
  lfnet::test::TempDir tmp;
  torch::manual_seed(5);
  // Values beyond [0, 1] too: both are clamped.
  LightField lf(torch::rand({1, 2, 3, 9, 13}) * 1.2 - 0.1);
  const lfnet::LightFieldViews coded(lfnet::encode_codes(lf.data()));
  for (const std::string ext : {"png", "tif"}) {
    io::write_light_field(lf, tmp / ("float-" + ext), {ext, 16});
    io::write_light_field(coded, tmp / ("coded-" + ext), {ext, 16});
    for (const auto& entry : fs::directory_iterator(tmp / ("float-" + ext))) {
      const auto other = tmp / ("coded-" + ext) / entry.path().filename();
      REQUIRE(fs::exists(other));
      CHECK(lfnet::test::read_bytes(entry.path().string()) ==
            lfnet::test::read_bytes(other.string()));
    }
  }
  // 8-bit files and the previews read the codes' values.
  io::write_light_field(coded, tmp / "coded-8", {"png", 8});
  const auto decoded = coded.decode();
  lfnet::test::require_close(io::read_light_field(tmp / "coded-8").data(), decoded.data(),
                             0.5 / 255 + 1e-7);
  CHECK(torch::equal(io::horizontal_epi(coded), io::horizontal_epi(decoded)));
  CHECK(torch::equal(io::vertical_epi(coded, 4, 2), io::vertical_epi(decoded, 4, 2)));
  CHECK(torch::equal(io::downscale_views(coded, 2).data(), io::downscale_views(decoded, 2).data()));
}

TEST_CASE("grey 16-bit views are read into 16-bit codes, exactly; others as float32", "[io]") {
  lfnet::test::TempDir tmp;
  torch::manual_seed(8);
  const LightField grey(torch::rand({1, 3, 2, 10, 12}));
  io::write_light_field(grey, tmp / "grey16", {"png", 16});
  const auto views = io::read_light_field_views(tmp / "grey16");
  REQUIRE(views.coded());
  // The codes decode to the very floats read_light_field gives.
  CHECK(torch::equal(views.decode().data(), io::read_light_field(tmp / "grey16").data()));
  {
    // Read into a file-backed tensor, as a large light field is, each view out of memory once
    // placed: the same codes.
    const lfnet::test::FileBackedEverything everything;
    const auto held = io::read_light_field_views(tmp / "grey16");
    CHECK(lfnet::file_backed(held.raw()) == lfnet::test::FileBackedEverything::available());
    CHECK(torch::equal(held.raw(), views.raw()));
  }
  // 8-bit views are not held in codes (their floats are k / 255 as read, not a code's value),
  // nor colour views, nor float ones.
  io::write_light_field(grey, tmp / "grey8", {"png", 8});
  io::write_light_field(LightField(torch::rand({3, 2, 2, 10, 12})), tmp / "rgb16", {"png", 16});
  io::write_light_field(grey, tmp / "float", {"tif", 32});
  for (const std::string dir : {"grey8", "rgb16", "float"}) {
    INFO(dir);
    const auto read = io::read_light_field_views(tmp / dir);
    CHECK_FALSE(read.coded());
    CHECK(torch::equal(read.raw(), io::read_light_field(tmp / dir).data()));
  }
}

TEST_CASE("light-field sequences round-trip through frame_K folders", "[io][sequence]") {
  lfnet::test::TempDir tmp;
  lfnet::LightFieldSequence seq(torch::rand({3, 1, 2, 3, 5, 6}));
  const auto dir = tmp / "seq";
  io::write_light_field_sequence(seq, dir, {"exr", 32});
  CHECK(fs::exists(fs::path(dir) / "frame_2" / "lf_2_3.exr"));
  CHECK(io::sequence_frames(dir) == 3);
  CHECK(torch::equal(io::read_light_field_sequence(dir).data(), seq.data()));
  // A still light field is no sequence; a gap in the frames is an error naming the frame.
  CHECK(io::sequence_frames(dir + "/frame_0") == 0);
  fs::rename(fs::path(dir) / "frame_1", fs::path(dir) / "frame_7");
  CHECK_THROWS_WITH(io::sequence_frames(dir), Catch::Contains("no frame_1"));
  CHECK_THROWS_AS(io::read_light_field_sequence(dir + "/frame_0"), lfnet::IoError);
  // Frames of two shapes are refused.
  fs::remove_all(fs::path(dir) / "frame_7");
  io::write_light_field(LightField(torch::rand({1, 2, 3, 5, 7})), fs::path(dir) / "frame_1",
                        {"exr", 32});
  CHECK_THROWS_WITH(io::read_light_field_sequence(dir), Catch::Contains("frame_1"));
}
