// Loads every real light field in ../shared/data; skipped when the folder is absent.
#include <catch2/catch.hpp>

#include <filesystem>

#include "lfnet/core/parallax.h"
#include "lfnet/io/light_field_io.h"
#include "support/test_support.h"

namespace io = lfnet::io;

TEST_CASE("every light field in ../shared/data loads with its documented shape", "[io][data]") {
  const std::string data = lfnet::test::shared_data_dir();
  if (data.empty()) {
    LFNET_SKIP("../shared/data is not beside the checkout");
  }
  struct Want {
    const char* folder;
    int64_t c, u, v, h, w;
    io::NamingScheme scheme;
  };
  const Want wants[] = {
      {"hci_antinous", 3, 9, 9, 512, 512, io::NamingScheme::kHciCam},
      {"lytro_bikes_4_eslf", 3, 8, 8, 376, 541, io::NamingScheme::kRowCol},
      {"lytro_occlusions_1_eslf", 3, 8, 8, 376, 541, io::NamingScheme::kRowCol},
      {"lytro_IMG_0288_eslf", 3, 8, 8, 376, 541, io::NamingScheme::kRowCol},
      {"lytro_Begonia", 3, 7, 7, 434, 625, io::NamingScheme::kTmRowCol},
  };
  for (const auto& want : wants) {
    const std::string dir = data + "/" + want.folder;
    INFO(dir);
    REQUIRE(io::scan_folder(dir).scheme == want.scheme);
    auto lf = io::read_light_field(dir);
    CHECK(lf.data().sizes() == torch::IntArrayRef({want.c, want.u, want.v, want.h, want.w}));
    auto c = lf.grey().central(5);
    CHECK(c.data().sizes() == torch::IntArrayRef({1, 5, 5, want.h, want.w}));
    // Real content: values in [0, 1], not constant.
    CHECK(lf.data().min().item<float>() >= 0.0f);
    CHECK(lf.data().max().item<float>() <= 1.0f);
    CHECK(lf.data().std().item<float>() > 0.01f);
    // Every camera's naming scheme is read in lfnet's orientation.
    const auto parallax = lfnet::check_parallax(c);
    INFO(parallax.summary());
    CHECK(parallax.verdict == lfnet::ParallaxVerdict::kAgree);
  }
  // The HCI disparity map is a PFM of the centre view's size.
  auto disp = io::read_pfm(data + "/hci_antinous/gt_disp_lowres.pfm");
  CHECK(disp.sizes() == torch::IntArrayRef({1, 512, 512}));
  CHECK(torch::isfinite(disp).all().item<bool>());
}
