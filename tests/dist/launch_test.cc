// dist::launch_local: every rank runs, and one failing rank stops the job with its name.
#include "lfnet/dist/launch.h"

#include <catch2/catch.hpp>

#include <chrono>
#include <filesystem>
#include <string>
#include <vector>

#include "lfnet/core/error.h"
#include "support/test_support.h"

using lfnet::dist::LaunchOptions;

TEST_CASE("launch_local runs every rank with its own arguments", "[dist][launch]") {
  lfnet::test::TempDir tmp;
  LaunchOptions o;
  o.ranks = 3;
  o.program = "/bin/sh";
  lfnet::dist::launch_local(o, [&](int64_t rank) {
    return std::vector<std::string>{
        "sh", "-c",
        "echo " + std::to_string(rank) + " > '" + tmp / ("rank" + std::to_string(rank)) + "'"};
  });
  for (int r = 0; r < 3; ++r) {
    CHECK(lfnet::test::read_bytes(tmp / ("rank" + std::to_string(r))) == std::to_string(r) + "\n");
  }
}

TEST_CASE("launch_local stops the job when a rank fails and names it", "[dist][launch]") {
  LaunchOptions o;
  o.ranks = 3;
  o.program = "/bin/sh";
  o.grace_s = 1;
  const auto start = std::chrono::steady_clock::now();
  CHECK_THROWS_WITH(
      lfnet::dist::launch_local(
          o,
          [](int64_t rank) {
            return std::vector<std::string>{"sh", "-c", rank == 1 ? "exit 3" : "exec sleep 60"};
          }),
      Catch::Contains("rank 1 of 3 exited with status 3") &&
          Catch::Contains("other ranks were stopped"));
  // The sleeping ranks were stopped, not waited for.
  CHECK(std::chrono::steady_clock::now() - start < std::chrono::seconds(30));
  o.ranks = 0;
  CHECK_THROWS_AS(lfnet::dist::launch_local(o, [](int64_t) { return std::vector<std::string>{}; }),
                  lfnet::ConfigError);
}
