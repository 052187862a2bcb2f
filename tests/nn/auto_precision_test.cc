// --precision auto's choice (nn/auto_precision.h): float32 unless the CPU has native bfloat16,
// measured faster than float32, and every model is verified in the bfloat16.json beside it.
#include "lfnet/nn/auto_precision.h"

#include <catch2/catch.hpp>

#include <cstdlib>
#include <fstream>

#include "support/test_support.h"

namespace {

// Sets LFNET_NATIVE_BFLOAT16 for one scope.
struct NativeBfloat16 {
  explicit NativeBfloat16(bool on) { ::setenv("LFNET_NATIVE_BFLOAT16", on ? "1" : "0", 1); }
  ~NativeBfloat16() { ::unsetenv("LFNET_NATIVE_BFLOAT16"); }
  NativeBfloat16(const NativeBfloat16&) = delete;
  NativeBfloat16& operator=(const NativeBfloat16&) = delete;
};

}  // namespace

TEST_CASE("file fingerprints follow the content, not the name", "[nn]") {
  lfnet::test::TempDir tmp;
  std::ofstream(tmp / "a.ckpt") << "weights";
  std::ofstream(tmp / "b.ckpt") << "weights";
  std::ofstream(tmp / "c.ckpt") << "weightz";
  const auto a = lfnet::nn::file_fingerprint(tmp / "a.ckpt");
  CHECK(a.size() == 16);
  CHECK(a == lfnet::nn::file_fingerprint(tmp / "b.ckpt"));
  CHECK(a != lfnet::nn::file_fingerprint(tmp / "c.ckpt"));
  // FNV-1a 64 of the empty file is its offset basis.
  std::ofstream(tmp / "empty.ckpt").close();
  CHECK(lfnet::nn::file_fingerprint(tmp / "empty.ckpt") == "cbf29ce484222325");
  CHECK_THROWS_AS(lfnet::nn::file_fingerprint(tmp / "none.ckpt"), lfnet::IoError);
}

TEST_CASE("precision auto picks bfloat16 only for verified models on a native CPU", "[nn]") {
  using lfnet::nn::choose_precision;
  using lfnet::nn::Precision;
  lfnet::test::TempDir tmp;
  const std::string model = tmp / "m.ckpt", other = tmp / "other.ckpt";
  std::ofstream(model) << "model";
  std::ofstream(other) << "another model";
  const auto fingerprint = lfnet::nn::file_fingerprint(model);
  {
    NativeBfloat16 native(false);
    const auto c = choose_precision({model}, "cpu");
    CHECK(c.precision == Precision::kFloat32);
    CHECK(c.reason.find("no native bfloat16") != std::string::npos);
  }
  NativeBfloat16 native(true);
  CHECK(choose_precision({}, "cpu").precision == Precision::kFloat32);
  CHECK(choose_precision({model}, "cuda").precision == Precision::kFloat32);
  auto c = choose_precision({model}, "cpu");
  CHECK(c.precision == Precision::kFloat32);
  CHECK(c.reason.find("no bfloat16.json") != std::string::npos);
  // Listed and verified, under another name: the content decides.
  std::ofstream(tmp / "bfloat16.json")
      << R"({"models": {"renamed.ckpt": {"fingerprint": ")" << fingerprint
      << R"(", "verified": true}, "other.ckpt": {"fingerprint": "0", "verified": true}}})";
  c = choose_precision({model}, "cpu");
  CHECK(c.precision == Precision::kBFloat16);
  // Every model must be verified.
  c = choose_precision({model, other}, "cpu");
  CHECK(c.precision == Precision::kFloat32);
  CHECK(c.reason.find("other.ckpt is not verified") != std::string::npos);
  // A model that loses too much is named so.
  std::ofstream(tmp / "bfloat16.json", std::ios::trunc)
      << R"({"models": {"m.ckpt": {"fingerprint": ")" << fingerprint
      << R"(", "verified": false}}})";
  c = choose_precision({model}, "cpu");
  CHECK(c.precision == Precision::kFloat32);
  CHECK(c.reason.find("loses more than the tolerance") != std::string::npos);
  // A damaged list or a missing model never throws: float32 with the reason.
  std::ofstream(tmp / "bfloat16.json", std::ios::trunc) << "{";
  CHECK(choose_precision({model}, "cpu").precision == Precision::kFloat32);
  CHECK(choose_precision({tmp / "none.ckpt"}, "cpu").precision == Precision::kFloat32);
}

TEST_CASE("precision auto measures whether bfloat16 is faster on this CPU", "[nn]") {
  // Measured: both times positive, and the same answer for the rest of the process.
  const auto speed = lfnet::nn::precision_speed();
  CHECK(speed.float32_ms > 0.0);
  CHECK(speed.bfloat16_ms > 0.0);
  CHECK(lfnet::nn::precision_speed().float32_ms == speed.float32_ms);
  CHECK(lfnet::nn::PrecisionSpeed{1.0, 0.85}.bfloat16_faster());
  CHECK_FALSE(lfnet::nn::PrecisionSpeed{1.0, 0.95}.bfloat16_faster());
  // LFNET_NATIVE_BFLOAT16 stands for the measurement too.
  {
    NativeBfloat16 native(true);
    CHECK(lfnet::nn::precision_speed().bfloat16_faster());
  }
  NativeBfloat16 native(false);
  CHECK_FALSE(lfnet::nn::precision_speed().bfloat16_faster());
}
