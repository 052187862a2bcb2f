#include "lfnet/core/runtime.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include "lfnet/core/error.h"

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
