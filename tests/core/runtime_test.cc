#include "lfnet/core/runtime.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <fstream>
#include <string>

#include "lfnet/core/error.h"
#include "lfnet/core/machine.h"

TEST_CASE("parse_device knows cpu and refuses CUDA clearly where there is none", "[core]") {
  CHECK(lfnet::parse_device("cpu") == c10::Device(c10::kCPU));
  CHECK_THROWS_AS(lfnet::parse_device("gpu"), lfnet::ConfigError);
  CHECK_THROWS_AS(lfnet::parse_device(""), lfnet::ConfigError);
  if (torch::cuda::is_available()) {
    CHECK(lfnet::parse_device("cuda").is_cuda());
    CHECK_THROWS_AS(lfnet::parse_device("cuda:999"), lfnet::ConfigError);
  } else {
    try {
      lfnet::parse_device("cuda");
      FAIL("cuda accepted without CUDA");
    } catch (const lfnet::ConfigError& e) {
      CHECK(std::string(e.what()).find("CUDA is not available") != std::string::npos);
    }
    CHECK_THROWS_AS(lfnet::parse_device("cuda:0"), lfnet::ConfigError);
  }
}

TEST_CASE("cpu_info reads a field of /proc/cpuinfo by its whole name", "[core]") {
  std::ifstream probe("/proc/cpuinfo");
  if (!probe.good()) {
    CHECK(lfnet::cpu_info("flags").empty());
    return;
  }
  // The first line with a field, read here by hand, is what cpu_info gives for that field.
  std::string line;
  while (std::getline(probe, line) && line.find(':') == std::string::npos) {
  }
  auto field = line.substr(0, line.find(':'));
  field.erase(field.find_last_not_of(" \t") + 1);
  auto value = line.substr(line.find(':') + 1);
  value.erase(0, value.find_first_not_of(' '));
  CHECK(lfnet::cpu_info(field) == value);
  // A field's name must match whole: a prefix of it is no field.
  CHECK(lfnet::cpu_info(field.substr(0, field.size() - 1)).empty());
  CHECK(lfnet::cpu_info("no such field").empty());
}
