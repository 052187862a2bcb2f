// The lfnet program's contract: --help, one-line errors, non-zero exits.
#include <catch2/catch.hpp>

#include "lfnet/io/light_field_io.h"
#include "support/test_support.h"

using lfnet::test::lfnet_binary;
using lfnet::test::run_command;

TEST_CASE("lfnet --help lists the subcommands", "[app]") {
  std::string out;
  REQUIRE(run_command(lfnet_binary() + " --help", out) == 0);
  CHECK(out.find("info") != std::string::npos);
  REQUIRE(run_command(lfnet_binary() + " info --help", out) == 0);
  CHECK(out.find("--lf") != std::string::npos);
}

TEST_CASE("lfnet info describes a light field folder", "[app]") {
  lfnet::test::TempDir tmp;
  lfnet::LightField lf(torch::full({1, 2, 3, 9, 10}, 0.25));
  lfnet::io::write_light_field(lf, tmp / "lf", {"png", 16});
  std::string out;
  REQUIRE(run_command(lfnet_binary() + " --threads 1 info --lf " + (tmp / "lf"), out) == 0);
  CHECK(out.find("2 x 3 views") != std::string::npos);
  CHECK(out.find("1x2x3x9x10") != std::string::npos);
  CHECK(out.find("lf_R_C") != std::string::npos);
}

TEST_CASE("errors are one line with a non-zero exit", "[app]") {
  std::string out;
  CHECK(run_command(lfnet_binary() + " info --lf /nonexistent/folder", out) != 0);
  CHECK(out.rfind("lfnet: error: ", 0) == 0);
  CHECK(out.find("/nonexistent/folder") != std::string::npos);
  CHECK(std::count(out.begin(), out.end(), '\n') == 1);
  CHECK(run_command(lfnet_binary() + " nosuchcommand", out) != 0);
  CHECK(out.find("lfnet: error: ") != std::string::npos);
  CHECK(run_command(lfnet_binary() + " --threads -3 info --lf x", out) != 0);
}
