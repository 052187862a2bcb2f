#include "lfnet/dict/dictionary.h"

#include <torch/serialize.h>
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>

#include "lfnet/core/error.h"
#include "lfnet/core/zip_check.h"
#include "support/test_support.h"

using lfnet::dict::Dictionary;
using lfnet::dict::load_dictionary;
using lfnet::dict::save_dictionary;

namespace {
Dictionary sample_dictionary(int64_t k) {
  torch::manual_seed(71);
  Dictionary d;
  auto atoms = torch::randn({2025, k});
  d.atoms = atoms / atoms.norm(2, 0, /*keepdim=*/true);
  d.training = {{"ksvd", {{"atoms", k}, {"sparsity", 10}}},
                {"history", {{{"iteration", 1}, {"coding_rmse", 0.05}}}},
                {"sources", {"a", "b"}}};
  return d;
}
}  // namespace

TEST_CASE("A dictionary survives save and load unchanged", "[dict][dictionary]") {
  lfnet::test::TempDir tmp;
  const Dictionary d = sample_dictionary(64);
  save_dictionary(d, tmp / "dictionary.ckpt");
  const Dictionary back = load_dictionary(tmp / "dictionary.ckpt");
  CHECK(torch::equal(back.atoms, d.atoms));
  CHECK(back.patch_shape == d.patch_shape);
  CHECK(back.training == d.training);
  CHECK(back.size() == 64);
  CHECK(back.dimension() == 2025);
  // No temporary file is left behind.
  int64_t files = 0;
  for (const auto& e : std::filesystem::directory_iterator(tmp.path())) files += e.exists();
  CHECK(files == 1);
}

TEST_CASE("A 1000-atom dictionary file stays under 10 MB", "[dict][dictionary]") {
  lfnet::test::TempDir tmp;
  save_dictionary(sample_dictionary(1000), tmp / "d.ckpt");
  const auto bytes = std::filesystem::file_size(tmp / "d.ckpt");
  INFO(bytes << " bytes");
  CHECK(bytes < 10u * 1000u * 1000u);
  CHECK(bytes >= 2025u * 1000u * 4u);
}

TEST_CASE("Broken dictionary files are clear errors", "[dict][dictionary]") {
  lfnet::test::TempDir tmp;
  save_dictionary(sample_dictionary(16), tmp / "good.ckpt");

  CHECK_THROWS_AS(load_dictionary(tmp / "missing.ckpt"), lfnet::IoError);

  // Truncated to half its size.
  {
    std::ifstream in(tmp / "good.ckpt", std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream out(tmp / "truncated.ckpt", std::ios::binary);
    out.write(bytes.data(), static_cast<std::streamsize>(bytes.size() / 2));
  }
  CHECK_THROWS_WITH(load_dictionary(tmp / "truncated.ckpt"), Catch::Contains("truncated"));
  CHECK_THROWS_AS(load_dictionary(tmp / "truncated.ckpt"), lfnet::CheckpointError);

  // Not an archive at all.
  {
    std::ofstream out(tmp / "text.ckpt");
    out << "hello, I am not a dictionary\n";
  }
  CHECK_THROWS_AS(load_dictionary(tmp / "text.ckpt"), lfnet::CheckpointError);

  // Another LibTorch archive (e.g. a network's weights).
  {
    torch::serialize::OutputArchive archive;
    archive.write("weight", torch::ones({3, 3}));
    archive.save_to(tmp / "foreign.ckpt");
  }
  CHECK_THROWS_WITH(load_dictionary(tmp / "foreign.ckpt"),
                    Catch::Contains("not an lfnet dictionary"));

  // A dictionary from a future format version.
  {
    nlohmann::json meta = {{"format", "lfnet-dictionary"},
                           {"version", 99},
                           {"patch_shape", {5, 5, 9, 9}},
                           {"atoms", 4}};
    torch::serialize::OutputArchive archive;
    archive.write("atoms", torch::zeros({2025, 4}));
    archive.write("lfnet_dictionary_meta", c10::IValue(meta.dump()));
    archive.save_to(tmp / "future.ckpt");
  }
  CHECK_THROWS_WITH(load_dictionary(tmp / "future.ckpt"), Catch::Contains("version 99"));

  // One byte changed anywhere in an entry's data (LibTorch's loader can crash on damaged code
  // or pickles): the zip checksums catch it first, naming the entry.
  std::string good;
  {
    std::ifstream in(tmp / "good.ckpt", std::ios::binary);
    good.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  CHECK_NOTHROW(lfnet::check_zip_integrity(tmp / "good.ckpt", "dictionary"));
  for (const char* entry : {"data.pkl", "constants.pkl", "data/0"}) {
    const auto at = good.find(std::string("/") + entry);
    REQUIRE(at != std::string::npos);
    // The entry's data follows its local header (30 bytes before the name, extra field after).
    auto bytes = good;
    const size_t header = bytes.rfind("PK\x03\x04", at);
    const size_t name_len =
        static_cast<uint8_t>(bytes[header + 26]) | static_cast<uint8_t>(bytes[header + 27]) << 8;
    const size_t extra_len =
        static_cast<uint8_t>(bytes[header + 28]) | static_cast<uint8_t>(bytes[header + 29]) << 8;
    bytes[header + 30 + name_len + extra_len] ^= 0x20;
    std::ofstream(tmp / "flipped.ckpt", std::ios::binary) << bytes;
    INFO(entry);
    CHECK_THROWS_WITH(load_dictionary(tmp / "flipped.ckpt"),
                      Catch::Contains("checksum mismatch in entry") && Catch::Contains(entry));
  }
}

TEST_CASE("Dictionaries are checked before they are written", "[dict][dictionary]") {
  lfnet::test::TempDir tmp;
  Dictionary d = sample_dictionary(8);
  d.patch_shape = {5, 5, 11, 11};
  CHECK_THROWS_WITH(save_dictionary(d, tmp / "x.ckpt"), Catch::Contains("3025"));
  d = sample_dictionary(8);
  d.atoms = d.atoms.to(torch::kFloat64);
  CHECK_THROWS_AS(save_dictionary(d, tmp / "x.ckpt"), lfnet::Error);
  CHECK(!std::filesystem::exists(tmp / "x.ckpt"));
}
