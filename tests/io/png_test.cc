#include "lfnet/io/png.h"

#include <catch2/catch.hpp>

#include <filesystem>
#include <string>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/io/light_field_io.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
namespace io = lfnet::io;

namespace {
// Random (H, W, C) samples of `bits` (16-bit ones held in int16, their bits).
torch::Tensor random_samples(int64_t h, int64_t w, int64_t c, int bits) {
  if (bits == 8) return torch::randint(0, 256, {h, w, c}, torch::kUInt8);
  return torch::randint(0, 65536, {h, w, c}, torch::kInt32).to(torch::kInt16);
}
}  // namespace

TEST_CASE("PNGs decode to their samples in every depth and channel count", "[io][png]") {
  lfnet::test::TempDir tmp;
  torch::manual_seed(11);
  int files = 0;
  for (const int bits : {8, 16}) {
    for (int64_t c = 1; c <= 4; ++c) {
      for (const auto& [h, w] : {std::pair<int64_t, int64_t>{1, 1}, {7, 13}, {40, 3}}) {
        // Smooth samples as well as noise: the compressor finds matches in the first.
        auto samples = random_samples(h, w, c, bits);
        if (h == 40) samples = samples.slice(0, 0, 1).expand({h, w, c}).contiguous();
        const std::string name = "b" + std::to_string(bits) + "_c" + std::to_string(c) + "_" +
                                 std::to_string(h) + "x" + std::to_string(w);
        const auto png = io::encode_png_samples(samples.data_ptr(), h, w, c, bits);
        lfnet::test::write_bytes(tmp / (name + ".png"), png);
        lfnet::test::write_bytes(
            tmp / (name + ".raw"),
            std::string(static_cast<const char*>(samples.data_ptr()),
                        static_cast<size_t>(samples.numel() * samples.element_size())));
        lfnet::write_json_file(tmp / (name + ".json"),
                               {{"height", h}, {"width", w}, {"channels", c}, {"bits", bits}});
        ++files;
        // OpenImageIO (libpng) reads grey and RGB files back to the same values.
        if (c == 1 || c == 3) {
          const double max = bits == 16 ? 65535.0 : 255.0;
          const auto read = io::read_image(tmp / (name + ".png"));
          const auto want = (bits == 16 ? samples.to(torch::kInt32).bitwise_and(0xffff)
                                        : samples.to(torch::kInt32))
                                .permute({2, 0, 1});
          CHECK(torch::equal((read * max).round().to(torch::kInt32), want));
        }
      }
    }
  }
  CHECK(files == 24);
  // Python's zlib and numpy decode them independently of libpng and libdeflate.
  const std::string python = lfnet::test::python_with("numpy");
  if (python.empty()) LFNET_SKIP("python3 with numpy not found");
  std::string out;
  const int status = lfnet::test::run_command(
      python + " " + LFNET_SOURCE_DIR + "/tests/io/check_png.py " + tmp.path().string(), out);
  INFO(out);
  CHECK(status == 0);
}

TEST_CASE("the PNG encoder refuses what PNG cannot hold", "[io][png]") {
  const auto samples = torch::zeros({4, 4, 5}, torch::kUInt8);
  CHECK_THROWS_WITH(io::encode_png_samples(samples.data_ptr(), 4, 4, 5, 8),
                    Catch::Contains("5 channels"));
  CHECK_THROWS_WITH(io::encode_png_samples(samples.data_ptr(), 4, 4, 1, 12),
                    Catch::Contains("12 bits"));
  CHECK_THROWS(io::encode_png_samples(samples.data_ptr(), 0, 4, 1, 8));
}

TEST_CASE("PNG views round [0, 1] to the nearest code; NaN and what lies outside clamp",
          "[io][png]") {
  lfnet::test::TempDir tmp;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const auto image = torch::tensor({0.0f, 1.0f, 0.5f, -0.2f, 1.7f, nan, 0.25f / 255, 0.75f / 255})
                         .reshape({1, 1, 8});
  io::write_image(tmp / "v8.png", image, 8);
  io::write_image(tmp / "v16.png", image, 16);
  const auto codes8 = (io::read_image(tmp / "v8.png") * 255).round().to(torch::kInt32);
  CHECK(torch::equal(codes8.flatten(), torch::tensor({0, 255, 128, 0, 255, 0, 0, 1})));
  const auto codes16 = (io::read_image(tmp / "v16.png") * 65535).round().to(torch::kInt32);
  CHECK(torch::equal(codes16.flatten(), torch::tensor({0, 65535, 32768, 0, 65535, 0, 64, 193})));
}
