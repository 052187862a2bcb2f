// pipeline::run_batch: finding the items under a folder, and one record per item and method
// without the program.
#include <catch2/catch.hpp>

#include <filesystem>

#include "lfnet/core/json.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/batch.h"
#include "lfnet/pipeline/simulate.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using namespace lfnet;

namespace {
// IN/b: a light field of known parallax; IN/acq: its coded capture with asp:2.
void write_inputs(const std::string& in) {
  const auto lf = test::parallax_light_field(5, 5, 20, 22, 1, -1);
  io::write_light_field(lf, in + "/b");
  auto phi = optics::make_phi(optics::PhiSpec::parse("asp:2"));
  pipeline::SimulateRequest s;
  s.lf = lf;
  s.phi = phi.get();
  fs::create_directories(in + "/acq");
  pipeline::write_acquisition(s, in + "/acq");
}
}  // namespace

TEST_CASE("discover_items finds acquisitions and light fields, and records what it cannot read",
          "[pipeline][batch]") {
  test::TempDir tmp;
  write_inputs(tmp / "in");
  io::write_light_field(test::parallax_light_field(5, 5, 20, 22, 1, -1), tmp / "in/scenes/a");
  fs::create_directories(tmp / "in/empty");
  fs::create_symlink(tmp / "in/nowhere", tmp / "in/broken");
  const auto items = pipeline::discover_items(tmp / "in");
  REQUIRE(items.size() == 4);  // sorted by name; the empty folder is no item
  CHECK(items[0].name == "acq");
  CHECK(items[0].kind == "reconstruct");
  CHECK(items[1].name == "b");
  CHECK(items[1].kind == "evaluate");
  CHECK(items[2].name == "broken");
  CHECK(items[2].kind == "unreadable");
  CHECK(items[2].error.find("broken link") != std::string::npos);
  CHECK(items[3].name == "scenes/a");
  CHECK(items[3].kind == "evaluate");
  CHECK_THROWS_WITH(pipeline::discover_items(tmp / "in/nowhere"),
                    Catch::Contains("is not a folder"));
}

TEST_CASE("run_batch writes one record per item and method and counts the failures",
          "[pipeline][batch]") {
  test::TempDir tmp;
  write_inputs(tmp / "in");
  pipeline::BatchOptions o;
  o.in = tmp / "in";
  o.out = tmp / "out";
  o.phi = "asp:2";
  o.methods = {"pinv", "no-parallax"};
  const auto summary = pipeline::run_batch(o);
  REQUIRE(summary.records.size() == 4);
  // The acquisition has no truth: no-parallax fails there and only there.
  CHECK(summary.failures == 1);
  CHECK(summary.records[0]["item"] == "acq");
  CHECK(summary.records[0]["method"] == "pinv");
  CHECK(summary.records[0]["status"] == "ok");
  CHECK(fs::exists(tmp.path() / "out/acq/pinv/reconstruction.json"));
  CHECK(summary.records[1]["status"] == "error");
  CHECK(summary.records[2]["item"] == "b");
  CHECK(summary.records[2]["psnr_db"].get<double>() >
        summary.records[3]["psnr_db"].get<double>());  // pinv beats no-parallax on parallax
  CHECK(fs::exists(tmp.path() / "out/summary.csv"));
  CHECK(read_json_file(tmp / "out/summary.json").size() == 4);
  CHECK(fs::exists(tmp.path() / "out/records/b__pinv.json"));
  // An unknown method is refused before any work, and the output stays as it was.
  o.methods = {"nosuch"};
  o.force = true;
  CHECK_THROWS_WITH(pipeline::run_batch(o), Catch::Contains("--methods"));
  CHECK(read_json_file(tmp / "out/summary.json").size() == 4);
}
