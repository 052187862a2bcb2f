#include "lfnet/pipeline/export.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <filesystem>
#include <string>

#include "lfnet/core/error.h"
#include "lfnet/nn/script.h"
#include "support/test_support.h"

namespace fs = std::filesystem;

TEST_CASE("export_model writes a file that runs like the checkpoint, and refuses to re-export it",
          "[pipeline][export]") {
  const std::string model = std::string(LFNET_SOURCE_DIR) + "/models/asp-n2.ckpt";
  lfnet::test::TempDir tmp;
  lfnet::pipeline::ExportRequest request;
  request.model = model;
  request.out = tmp / "asp-n2.pt";
  request.check = 16;
  const auto r = lfnet::pipeline::export_model(request);
  CHECK(r.phi == "asp:2");
  CHECK(r.branches == "net");
  CHECK(r.phases >= 1);
  CHECK(r.max_difference <= 1e-5);
  CHECK(r.megabytes == Approx(static_cast<double>(fs::file_size(request.out)) / 1e6));
  CHECK(lfnet::nn::is_script_file(request.out));
  // An existing file is kept unless forced; an exported file is not a checkpoint.
  CHECK_THROWS_AS(lfnet::pipeline::export_model(request), lfnet::Error);
  request.force = true;
  CHECK_NOTHROW(lfnet::pipeline::export_model(request));
  lfnet::pipeline::ExportRequest again = request;
  again.model = request.out;
  again.out = tmp / "again.pt";
  CHECK_THROWS_WITH(lfnet::pipeline::export_model(again), Catch::Contains("already an exported"));
  CHECK_FALSE(fs::exists(again.out));
}
