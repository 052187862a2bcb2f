// A time budget (pipeline/budget.h): the calibration's line through its timings, its file and
// fingerprint, which zoo models a budget chooses among, and the choice itself.
#include <catch2/catch.hpp>

#include <cstdlib>
#include <filesystem>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/runtime.h"
#include "lfnet/pipeline/budget.h"
#include "support/small_nets.h"
#include "support/test_support.h"

namespace fs = std::filesystem;
using namespace lfnet;

namespace {

// A zoo of small lfnet nets with the measured blocks given, and a calibration beside it.
struct SmallZoo {
  test::TempDir tmp;
  std::string dir = (tmp.path() / "zoo").string();
  std::string calibration = (tmp.path() / "cache" / "calibration.json").string();

  SmallZoo(const nlohmann::json& cards) {
    fs::create_directories(dir);
    nlohmann::json zoo = {{"about", "test"}, {"models", cards}};
    uint64_t seed = 1;
    for (auto& card : zoo["models"]) {
      const auto file = card["name"].get<std::string>() + ".ckpt";
      card["file"] = file;
      test::save_small_image_net(card.value("colour", "grey") == "grey" ? "" : "RGGB", seed++,
                                 (fs::path(dir) / file).string());
    }
    write_json_file((fs::path(dir) / "zoo.json").string(), zoo);
    ::setenv("LFNET_MODELS", dir.c_str(), 1);
    ::setenv("LFNET_CALIBRATION", calibration.c_str(), 1);
  }
  ~SmallZoo() {
    ::unsetenv("LFNET_MODELS");
    ::unsetenv("LFNET_CALIBRATION");
  }
  std::string path(const std::string& name) const {
    return (fs::path(dir) / name).string() + ".ckpt";
  }

  // A calibration of this machine in which `model` takes `seconds` per megapixel.
  void time(pipeline::Calibration& c, const std::string& model, double seconds_per_mp) const {
    pipeline::CalibrationEntry e;
    e.model = model;
    e.camera = "asp:2";
    e.colour = "grey";
    e.file_bytes = model == "pinv" ? 0 : static_cast<int64_t>(fs::file_size(path(model)));
    e.setting = pipeline::run_setting(model == "pinv" ? "" : path(model), "cpu", std::nullopt);
    e.timings = {{250000, 0.25 * seconds_per_mp}, {1000000, seconds_per_mp}};
    e.fit();
    c.put(e);
  }
};

nlohmann::json card(const std::string& name, std::optional<double> validation_mean,
                    double benchmark_mean) {
  nlohmann::json c = {{"name", name}, {"camera", "asp:2"}, {"colour", "grey"}};
  c["measured"]["benchmark"] = {
      {"section", "cross-scene"},
      {"margins_over_pinv_db", {{"a", benchmark_mean - 1}, {"b", benchmark_mean + 1}}}};
  if (validation_mean) c["measured"]["validation"]["mean_margin_over_pinv_db"] = *validation_mean;
  return c;
}

}  // namespace

TEST_CASE("a calibration entry predicts seconds by the line through its timings", "[budget]") {
  pipeline::CalibrationEntry e;
  e.timings = {{100, 1.5}, {400, 3.0}};
  e.fit();
  CHECK(e.fixed == Approx(1.0));
  CHECK(e.per_pixel == Approx(0.005));
  CHECK(e.predict(1000) == Approx(6.0));
  // Timings noisier than the size's effect: the larger alone, proportional to pixels.
  e.timings = {{100, 2.0}, {400, 1.6}};
  e.fit();
  CHECK(e.fixed == 0);
  CHECK(e.predict(800) == Approx(3.2));
  // It keeps its key and its line through a file.
  e.model = "m";
  e.camera = "asp:2";
  e.colour = "grey";
  e.setting = {"cpu", 3, nn::Precision::kBFloat16};
  const auto back = pipeline::CalibrationEntry::from_json(e.to_json());
  CHECK(back.model == "m");
  CHECK(back.setting.threads == 3);
  CHECK(back.setting.precision == nn::Precision::kBFloat16);
  CHECK(back.predict(800) == Approx(3.2));
}

TEST_CASE("a calibration holds for its machine only", "[budget]") {
  test::TempDir tmp;
  const auto path = (tmp.path() / "sub" / "calibration.json").string();
  // Missing: empty, with this machine's fingerprint.
  auto c = pipeline::read_calibration(path);
  CHECK(c.entries.empty());
  CHECK(c.machine == pipeline::machine_fingerprint());
  pipeline::CalibrationEntry e;
  e.model = "m";
  e.camera = "asp:2";
  e.colour = "grey";
  e.timings = {{100, 1.0}, {400, 2.0}};
  e.fit();
  c.put(e);
  c.put(e);  // the same key replaces
  REQUIRE(c.entries.size() == 1);
  pipeline::write_calibration(path, c);
  const auto back = pipeline::read_calibration(path);
  REQUIRE(back.entries.size() == 1);
  CHECK(back.find("m", "asp:2", "grey", e.setting) != nullptr);
  // Another thread count is another setting.
  auto other = e.setting;
  other.threads += 1;
  CHECK(back.find("m", "asp:2", "grey", other) == nullptr);
  // Another machine's (or lfnet version's) file is not used.
  auto doc = read_json_file(path);
  doc["machine"]["cpu"] = "another CPU";
  write_json_file(path, doc);
  CHECK(pipeline::read_calibration(path).entries.empty());
  // Nor an unreadable one.
  test::write_bytes(path, "{not json");
  CHECK(pipeline::read_calibration(path).entries.empty());
}

TEST_CASE("a budget ranks its camera's zoo networks by their validation margin", "[budget]") {
  SmallZoo zoo(
      nlohmann::json::array({card("fast", 1.0, 1.5), card("best", 2.6, 2.0),
                             card("unvalidated", std::nullopt, 9.0), card("middle", 2.4, 3.0)}));
  const auto z = pipeline::read_zoo(zoo.dir);
  auto names = [](const std::vector<pipeline::BudgetCandidate>& cs) {
    std::vector<std::string> out;
    for (const auto& c : cs) out.push_back(c.name);
    return out;
  };
  // A card without the validation figure the others have is left out.
  const auto ranked = pipeline::budget_candidates(z, "asp:2", "grey");
  CHECK(names(ranked) == std::vector<std::string>{"best", "middle", "fast"});
  CHECK(ranked[0].basis == "validation");
  CHECK(ranked[0].accuracy == Approx(2.6));
  CHECK(pipeline::budget_candidates(z, "asp:2", "RGGB").empty());
  CHECK(pipeline::budget_candidates(z, "mask:2", "grey").empty());

  // Where no card has validation figures, the benchmark's mean margin ranks them.
  SmallZoo bench_only(
      nlohmann::json::array({card("x", std::nullopt, 1.0), card("y", std::nullopt, 3.0)}));
  const auto by_benchmark =
      pipeline::budget_candidates(pipeline::read_zoo(bench_only.dir), "asp:2", "grey");
  CHECK(names(by_benchmark) == std::vector<std::string>{"y", "x"});
  CHECK(by_benchmark[0].basis == "cross-scene");
  CHECK(by_benchmark[0].accuracy == Approx(3.0));
}

TEST_CASE("a budget runs the most accurate model that fits, or says none does", "[budget]") {
  SmallZoo zoo(nlohmann::json::array(
      {card("fast", 1.0, 1.5), card("best", 2.6, 2.0), card("middle", 2.4, 3.0)}));
  auto c = pipeline::read_calibration(zoo.calibration);
  zoo.time(c, "fast", 0.4);
  zoo.time(c, "middle", 1.0);
  zoo.time(c, "best", 3.0);
  zoo.time(c, "pinv", 0.2);
  pipeline::write_calibration(zoo.calibration, c);
  const int64_t mp = 1000000;
  auto choose = [&](double budget, int64_t pixels) {
    return pipeline::choose_within_budget(budget, "asp:2", "grey", pixels, "cpu", std::nullopt);
  };
  const auto roomy = choose(10, mp);
  CHECK(roomy.model == "best");
  CHECK(roomy.path == zoo.path("best"));
  CHECK(roomy.predicted_seconds == Approx(3.0));
  CHECK(roomy.candidates.size() == 3);
  CHECK(choose(2.9, mp).model == "middle");
  CHECK(choose(0.5, mp).model == "fast");
  // Smaller images take less: a quarter of the pixels fits the best in a quarter of its time.
  CHECK(choose(0.8, mp / 4).model == "best");
  const auto record = choose(1.5, mp).record();
  CHECK(record["model"] == "middle");
  CHECK(record["predicted_seconds"].get<double>() == Approx(1.0));
  CHECK(record["seconds"].get<double>() == Approx(1.5));
  CHECK_THROWS_WITH(choose(0.3, mp), Catch::Contains("no zoo model for asp:2 (grey) fits") &&
                                         Catch::Contains("the fastest, fast, needs 0.40 s") &&
                                         Catch::Contains("--method pinv needs 0.20 s"));
  CHECK_THROWS_WITH(pipeline::choose_within_budget(1, "mask:2", "grey", mp, "cpu", std::nullopt),
                    Catch::Contains("no measured model for mask:2"));
  // Nothing was timed: the calibration held every model.
  CHECK(pipeline::read_calibration(zoo.calibration).entries.size() == 4);
}

TEST_CASE("a budget times what the calibration lacks, once, and a changed file again", "[budget]") {
  SmallZoo zoo(nlohmann::json::array({card("only", 1.0, 1.0)}));
  const auto first =
      pipeline::choose_within_budget(1000, "asp:2", "grey", int64_t{64} * 64, "cpu", std::nullopt);
  CHECK(first.model == "only");
  const auto c = pipeline::read_calibration(zoo.calibration);
  REQUIRE(c.entries.size() == 2);  // the model and its camera's pinv
  const auto setting = pipeline::run_setting(zoo.path("only"), "cpu", std::nullopt);
  const auto* e = c.find("only", "asp:2", "grey", setting);
  REQUIRE(e != nullptr);
  CHECK(e->timings.size() == 2);
  CHECK(e->timings[1].first == int64_t{593} * 840);
  CHECK(e->timings[0].first == int64_t{297} * 420);
  CHECK(e->timings[1].second > 0);
  CHECK(e->setting.threads == thread_count());
  // Told the timings, the next choice reads them: a file with other timings is kept as it is.
  auto edited = c;
  zoo.time(edited, "only", 123.0);
  pipeline::write_calibration(zoo.calibration, edited);
  CHECK(pipeline::choose_within_budget(1000, "asp:2", "grey", 1000000, "cpu", std::nullopt)
            .predicted_seconds == Approx(123.0));
  // A model file that changed is timed again.
  test::save_small_image_net("", 99, zoo.path("only"), 8);
  const auto again =
      pipeline::choose_within_budget(1000, "asp:2", "grey", 1000000, "cpu", std::nullopt);
  CHECK(again.predicted_seconds < 100);
}

TEST_CASE(
    "a budget is refused with a model, a method, a self-ensemble, self-calibration or per_patch",
    "[budget]") {
  CHECK_NOTHROW(pipeline::check_budget_request({}));
  CHECK_THROWS_WITH(pipeline::check_budget_request({true, false, false, false}),
                    Catch::Contains("give --budget or --model, not both"));
  CHECK_THROWS_WITH(pipeline::check_budget_request({false, true, false, false}),
                    Catch::Contains("leave out --method"));
  CHECK_THROWS_WITH(pipeline::check_budget_request({false, false, true, false}),
                    Catch::Contains("--self-ensemble"));
  CHECK_THROWS_WITH(pipeline::check_budget_request({false, false, false, true}),
                    Catch::Contains("--self-calibrate"));
  CHECK_THROWS_WITH(pipeline::check_budget_request({false, false, false, false, true}),
                    Catch::Contains("leave out --mode per_patch"));
}
