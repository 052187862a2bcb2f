#include "lfnet/core/json.h"

#include <catch2/catch.hpp>

#include <fstream>

#include "support/test_support.h"

TEST_CASE("the JSON reader rejects unknown keys and names the path", "[core][json]") {
  auto doc = nlohmann::json::parse(R"({"train": {"lr": 0.001, "epochs": 3, "lrr": 1}})");
  lfnet::JsonReader root(doc, "$");
  auto train = root.child("train");
  double lr = 0;
  int epochs = 0;
  train.get("lr", lr);
  train.get("epochs", epochs);
  CHECK(lr == 0.001);
  CHECK(epochs == 3);
  try {
    train.finish();
    FAIL("unknown key accepted");
  } catch (const lfnet::ConfigError& e) {
    CHECK(std::string(e.what()).find("$.train.lrr") != std::string::npos);
  }
}

TEST_CASE("the JSON reader reports wrong types and missing keys with their path", "[core][json]") {
  auto doc = nlohmann::json::parse(R"({"n": "two"})");
  lfnet::JsonReader r(doc, "$.phi");
  int n = 0;
  try {
    r.get("n", n);
    FAIL("string accepted as int");
  } catch (const lfnet::ConfigError& e) {
    CHECK(std::string(e.what()).find("$.phi.n") != std::string::npos);
  }
  std::string name;
  CHECK_THROWS_WITH(r.require("name", name), Catch::Contains("$.phi.name"));
}

TEST_CASE("the JSON reader is type-strict: no silent rounding, casting or wrapping",
          "[core][json]") {
  auto doc = nlohmann::json::parse(R"({"half": 2.5, "whole": 3.0, "big": 1e15, "flag": 1,
      "neg": -1, "huge": 1e300, "text": 7, "yes": true, "list": [1, 2.5], "num": 4})");
  lfnet::JsonReader r(doc, "$.x");
  int64_t i = 0;
  CHECK_THROWS_WITH(r.get("half", i),
                    Catch::Contains("$.x.half") && Catch::Contains("whole number"));
  REQUIRE(r.get("whole", i));
  CHECK(i == 3);
  REQUIRE(r.get("big", i));
  CHECK(i == 1000000000000000);
  int small = 0;
  CHECK_THROWS_WITH(r.get("big", small), Catch::Contains("outside the range"));
  CHECK_THROWS_WITH(r.get("huge", i), Catch::Contains("$.x.huge"));
  uint64_t u = 0;
  CHECK_THROWS_WITH(r.get("neg", u), Catch::Contains("$.x.neg"));
  bool b = false;
  CHECK_THROWS_WITH(r.get("flag", b), Catch::Contains("true or false"));
  CHECK_THROWS_WITH(r.get("yes", i), Catch::Contains("whole number"));
  std::string t;
  CHECK_THROWS_WITH(r.get("text", t), Catch::Contains("expected a string"));
  std::vector<int64_t> list;
  CHECK_THROWS_WITH(r.get("list", list), Catch::Contains("$.x.list[1]"));
  double d = 0;
  CHECK_THROWS_WITH(r.get("yes", d), Catch::Contains("expected a number"));
  REQUIRE(r.get("num", d));
  CHECK(d == 4.0);
}

TEST_CASE("malformed JSON is a ConfigError with the byte offset", "[core][json]") {
  CHECK_THROWS_WITH(lfnet::parse_json("{\"a\": 1,,}", "cfg.json"), Catch::Contains("cfg.json"));
  CHECK_THROWS_AS(lfnet::parse_json("{", "x"), lfnet::ConfigError);
}

TEST_CASE("a key given twice in one object is refused with its path, not silently dropped",
          "[core][json]") {
  CHECK_THROWS_WITH(lfnet::parse_json(R"({"training": {"lr": 1, "lr": 2}})", "cfg.json"),
                    Catch::Contains("cfg.json: $.training.lr: the key appears twice"));
  CHECK_THROWS_WITH(
      lfnet::parse_json(R"({"stages": [{"name": "ae"}, {"name": "cnn", "name": "joint"}]})", "c"),
      Catch::Contains("$.stages[].name"));
  CHECK_THROWS_WITH(lfnet::parse_json(R"({"a": 1, "b": {}, "a": 3})", "c"),
                    Catch::Contains("c: $.a: the key appears twice"));
  // The same key in different objects is no duplicate.
  const auto j =
      lfnet::parse_json(R"({"a": {"x": 1}, "b": {"x": 2}, "c": [{"x": 3}, {"x": 4}]})", "c");
  CHECK(j["c"][1]["x"] == 4);
}

TEST_CASE("JSON files are written atomically and read back", "[core][json]") {
  lfnet::test::TempDir tmp;
  nlohmann::json j = {{"a", 1}, {"b", {1, 2, 3}}};
  lfnet::write_json_file(tmp / "x.json", j);
  CHECK(lfnet::read_json_file(tmp / "x.json") == j);
  CHECK_THROWS_AS(lfnet::read_json_file(tmp / "missing.json"), lfnet::IoError);
}

TEST_CASE("an option's JSON is inline text or a file, and errors name the option", "[core][json]") {
  lfnet::test::TempDir tmp;
  const nlohmann::json j = {{"a", 1}};
  lfnet::write_json_file(tmp / "x.json", j);
  CHECK(lfnet::read_json_argument(R"({"a": 1})", "--opt") == j);
  CHECK(lfnet::read_json_argument(tmp / "x.json", "--opt") == j);
  CHECK_THROWS_WITH(lfnet::read_json_argument(R"({"a": )", "--opt"),
                    Catch::StartsWith("--opt: malformed JSON"));
  CHECK_THROWS_WITH(lfnet::read_json_argument(tmp / "missing.json", "--opt"),
                    Catch::StartsWith("--opt " + (tmp / "missing.json") + ": cannot read"));
  { std::ofstream(tmp / "bad.json") << "[1,"; }
  CHECK_THROWS_AS(lfnet::read_json_argument(tmp / "bad.json", "--opt"), lfnet::ConfigError);
  CHECK_THROWS_WITH(lfnet::read_json_argument(tmp / "bad.json", "--opt"),
                    Catch::StartsWith("--opt " + (tmp / "bad.json") + ": malformed JSON"));
}

TEST_CASE("json_differences names only the fields that differ, briefly", "[core][json]") {
  auto a = nlohmann::json::parse(R"({"name": "asp", "n": 2, "params": {"pair_alpha": 90}})");
  auto b = nlohmann::json::parse(R"({"name": "asp", "n": 2, "params": {"pair_alpha": 0}})");
  CHECK(lfnet::json_differences(a, b, "model", "data") == "params.pair_alpha (model 90, data 0)");
  CHECK(lfnet::json_differences(a, a, "model", "data").empty());
  // Another model: its parameters are not listed one by one.
  auto c = nlohmann::json::parse(
      R"({"name": "calibrated", "n": 2, "params": {"period": 1, "weights": [1, 2, 3]}})");
  CHECK(lfnet::json_differences(a, c, "model", "data") ==
        "name (model \"asp\", data \"calibrated\"); params (another model's)");
  // Long lists are summarised.
  auto d = c;
  d["params"]["weights"] = std::vector<double>(50, 0.25);
  CHECK(lfnet::json_differences(c, d, "A", "B") ==
        "params.weights (A [1,2,3], B a list of 50 values)");
}
