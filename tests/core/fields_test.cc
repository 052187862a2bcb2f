// core/fields.h: one field list drives strict reading and writing, nested, optional and enum
// fields included.
#include "lfnet/core/fields.h"

#include <catch2/catch.hpp>

#include <optional>
#include <string>
#include <vector>

namespace sample {

enum class Colour { kRed, kGreen };

std::string to_string(Colour c) { return c == Colour::kRed ? "red" : "green"; }
Colour from_string(const std::string& name, Colour) {
  if (name == "red") return Colour::kRed;
  if (name == "green") return Colour::kGreen;
  throw lfnet::ConfigError("'" + name + "' is unknown (known: red, green)");
}

struct Inner {
  int64_t size = 3;
  template <typename Fields>
  void fields(Fields& f) {
    f("size", size);
  }
};

struct Outer {
  double rate = 0.5;
  std::string name = "a";
  std::vector<int64_t> steps = {1, 2};
  bool on = false;
  Colour colour = Colour::kRed;
  std::vector<Colour> palette = {Colour::kGreen};
  Inner inner;
  std::optional<Inner> extra;
  template <typename Fields>
  void fields(Fields& f) {
    f("rate", rate);
    f("name", name);
    f("steps", steps);
    f("on", on);
    f("colour", colour);
    f("palette", palette);
    f("inner", inner);
    f("extra", extra);
  }
};

Outer read(const nlohmann::json& j) {
  Outer o;
  lfnet::JsonReader r(j, "$.x");
  lfnet::read_fields(r, o);
  r.finish();
  return o;
}

struct Bounded {
  double rate = 0.5;
  std::vector<int64_t> sizes = {1};
  template <typename Fields>
  void fields(Fields& f) {
    f("rate", rate, lfnet::Range::above(0, 1));
    f("sizes", sizes, lfnet::Range::closed(1, 8));
  }
};

}  // namespace sample

TEST_CASE("a field list writes every field and reads back what it wrote", "[core][fields]") {
  const sample::Outer defaults;
  const auto j = lfnet::fields_to_json(defaults);
  CHECK(j == nlohmann::json::parse(R"({"rate": 0.5, "name": "a", "steps": [1, 2], "on": false,
                                      "colour": "red", "palette": ["green"],
                                      "inner": {"size": 3}})"));
  sample::Outer changed;
  changed.rate = 2.25;
  changed.colour = sample::Colour::kGreen;
  changed.palette = {sample::Colour::kRed, sample::Colour::kGreen, sample::Colour::kRed};
  changed.inner.size = 7;
  changed.extra = sample::Inner{9};
  const auto written = lfnet::fields_to_json(changed);
  CHECK(written["extra"] == nlohmann::json{{"size", 9}});
  const auto back = sample::read(written);
  CHECK(back.rate == 2.25);
  CHECK(back.colour == sample::Colour::kGreen);
  CHECK(written["palette"] == nlohmann::json{"red", "green", "red"});
  CHECK((back.palette == changed.palette));
  CHECK(back.inner.size == 7);
  REQUIRE(back.extra.has_value());
  CHECK(back.extra->size == 9);
  CHECK(lfnet::fields_to_json(back) == written);
}

TEST_CASE("reading a field list keeps defaults and refuses what is wrong with its path",
          "[core][fields]") {
  auto o = sample::read(nlohmann::json::parse(R"({"name": "b", "extra": {}})"));
  CHECK(o.name == "b");
  CHECK(o.rate == 0.5);
  REQUIRE(o.extra.has_value());  // an empty object sets an optional struct to its defaults
  CHECK(o.extra->size == 3);
  CHECK_FALSE(sample::read(nlohmann::json::object()).extra.has_value());
  CHECK_THROWS_WITH(sample::read(nlohmann::json::parse(R"({"rat": 1})")),
                    Catch::Contains("$.x.rat") && Catch::Contains("unknown key"));
  CHECK_THROWS_WITH(sample::read(nlohmann::json::parse(R"({"inner": {"size": 2.5}})")),
                    Catch::Contains("$.x.inner.size") && Catch::Contains("whole number"));
  CHECK_THROWS_WITH(sample::read(nlohmann::json::parse(R"({"inner": {"sise": 2}})")),
                    Catch::Contains("$.x.inner.sise"));
  CHECK_THROWS_WITH(sample::read(nlohmann::json::parse(R"({"on": 1})")),
                    Catch::Contains("$.x.on") && Catch::Contains("true or false"));
  CHECK_THROWS_WITH(sample::read(nlohmann::json::parse(R"({"colour": "blue"})")),
                    Catch::Contains("$.x.colour") && Catch::Contains("red, green"));
  CHECK(sample::read(nlohmann::json::parse(R"({"palette": []})")).palette.empty());
  CHECK_THROWS_WITH(sample::read(nlohmann::json::parse(R"({"palette": ["red", "blue"]})")),
                    Catch::Contains("$.x.palette[1]") && Catch::Contains("red, green"));
  CHECK_THROWS_WITH(sample::read(nlohmann::json::parse(R"({"palette": "red"})")),
                    Catch::Contains("$.x.palette") && Catch::Contains("list"));
  CHECK_THROWS_WITH(sample::read(nlohmann::json::parse(R"({"palette": ["red", 2]})")),
                    Catch::Contains("$.x.palette[1]") && Catch::Contains("string"));
  CHECK_THROWS_WITH(sample::read(nlohmann::json::parse(R"({"colour": 1})")),
                    Catch::Contains("$.x.colour") && Catch::Contains("string"));
  CHECK_THROWS_WITH(sample::read(nlohmann::json::parse(R"({"inner": 3})")),
                    Catch::Contains("$.x.inner"));
}

TEST_CASE("with_path puts the reader's path in front of a validation error", "[core][fields]") {
  const auto j = nlohmann::json::object();
  lfnet::JsonReader r(j, "$.training");
  CHECK_THROWS_WITH(lfnet::with_path(r, [] { throw lfnet::ConfigError("epochs: must be >= 1"); }),
                    "$.training.epochs: must be >= 1");
}

TEST_CASE("a field's range refuses what lies outside it, with the path and the range", "[fields]") {
  using lfnet::options_from_json;
  const auto ok = options_from_json<sample::Bounded>({{"rate", 1.0}, {"sizes", {1, 8}}}, "$");
  CHECK(ok.rate == 1.0);
  CHECK(ok.sizes == std::vector<int64_t>{1, 8});
  CHECK_THROWS_WITH(options_from_json<sample::Bounded>({{"rate", 0.0}}, "$"),
                    "$.rate: must lie in (0, 1], got 0");
  CHECK_THROWS_WITH(options_from_json<sample::Bounded>({{"rate", 1e300}}, "$"),
                    "$.rate: must lie in (0, 1], got 1e+300");
  CHECK_THROWS_WITH(options_from_json<sample::Bounded>({{"sizes", {2, 9}}}, "$"),
                    "$.sizes[1]: must lie in [1, 8], got 9");
  // Writing ignores the range.
  CHECK(lfnet::fields_to_json(ok) == nlohmann::json{{"rate", 1.0}, {"sizes", {1, 8}}});
}
