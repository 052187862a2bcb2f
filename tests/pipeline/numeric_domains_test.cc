// Every numeric field of every JSON input has a domain (docs/robustness.md, "Bad input"): the
// test walks the field lists of the Options structs each input is read into, sets every numeric
// field in turn to an absurd value (1e300 and -1e300, or +-2^40 for whole numbers), reads the
// input as the commands do and expects a ConfigError that names the field. A field added to any
// of these structs is covered without a new test case.
#include <catch2/catch.hpp>

#include <fstream>
#include <functional>
#include <string>
#include <type_traits>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/core/fields.h"
#include "lfnet/cv/opencv.h"
#include "lfnet/data/patch_dataset.h"
#include "lfnet/dict/ksvd.h"
#include "lfnet/dict/patch_sampling.h"
#include "lfnet/dict/sparse_coding.h"
#include "lfnet/nn/learned_phi.h"
#include "lfnet/nn/network.h"
#include "lfnet/optics/calibration.h"
#include "lfnet/optics/sensor.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/experiment.h"
#include "lfnet/pipeline/sets.h"
#include "lfnet/recon/denoise.h"
#include "lfnet/scene/random_scene.h"
#include "lfnet/train/trainer.h"
#include "support/test_support.h"

namespace {

using nlohmann::json;

template <typename T>
struct IsNumericVector : std::false_type {};
template <typename T, typename A>
struct IsNumericVector<std::vector<T, A>>
    : std::bool_constant<std::is_arithmetic_v<T> && !std::is_same_v<T, bool>> {};

struct NumericField {
  std::string pointer;  // a JSON pointer into the input, e.g. /training/lr
  bool floating = false;
  bool list = false;
};

// Collects the numeric fields of a field list, nested Options structs included.
struct CollectNumeric {
  std::string prefix;
  std::vector<NumericField>* out;

  template <typename T>
  void operator()(const char* key, T& value) {
    const std::string pointer = prefix + "/" + key;
    if constexpr (lfnet::detail::HasFields<T>::value) {
      CollectNumeric nested{pointer, out};
      value.fields(nested);
    } else if constexpr (lfnet::detail::IsOptional<T>::value) {
      typename T::value_type inner;
      CollectNumeric nested{pointer, out};
      inner.fields(nested);
    } else if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) {
      out->push_back({pointer, std::is_floating_point_v<T>, false});
    } else if constexpr (IsNumericVector<T>::value) {
      out->push_back({pointer, std::is_floating_point_v<typename T::value_type>, true});
    }
  }
  template <typename T>
  void operator()(const char* key, T& value, const lfnet::Range&) {
    (*this)(key, value);
  }
};

template <typename T>
std::vector<NumericField> numeric_fields(const std::string& prefix) {
  T options;
  std::vector<NumericField> out;
  CollectNumeric collect{prefix, &out};
  options.fields(collect);
  return out;
}

// A seed takes any value of its type (a set entry's "random" is its scene's seed): no absurd
// value to refuse.
bool is_seed(const std::string& pointer) {
  const auto key = pointer.substr(pointer.rfind('/') + 1);
  return key == "seed" || key == "random_seed" || key == "random";
}

// For every field, every absurd value that `read` (reading the whole input) accepts or refuses
// without naming the field: one line each, empty when every value is refused by name.
std::vector<std::string> unguarded(const json& base, const std::vector<NumericField>& fields,
                                   const std::function<void(const json&)>& read) {
  std::vector<std::string> found;
  for (const auto& field : fields) {
    if (is_seed(field.pointer)) continue;
    const std::vector<json> values = field.floating
                                         ? std::vector<json>{1e300, -1e300}
                                         : std::vector<json>{int64_t{1} << 40, -(int64_t{1} << 40)};
    const auto key = field.pointer.substr(field.pointer.rfind('/') + 1);
    for (const auto& value : values) {
      json input = base;
      input[json::json_pointer(field.pointer)] = field.list ? json::array({value}) : value;
      const auto problem = lfnet::test::unrefused(input, key, read);
      if (problem.empty()) continue;
      std::string line = field.pointer;
      line.append(" = ").append(value.dump()).append(problem);
      found.push_back(line);
    }
  }
  return found;
}

void check_guarded(const std::vector<std::string>& found) {
  std::string all;
  for (const auto& line : found) all += line + "\n";
  INFO(all);
  CHECK(found.empty());
}

template <typename... Ts>
std::vector<NumericField> fields_of(const std::string& prefix) {
  std::vector<NumericField> out;
  (
      [&] {
        auto f = numeric_fields<Ts>(prefix);
        out.insert(out.end(), f.begin(), f.end());
      }(),
      ...);
  return out;
}

json base_config() {
  return json::parse(R"({
    "name": "domains",
    "phi": "asp:2",
    "data": {"random_scenes": 1, "random_options": {"height": 64, "width": 64}},
    "dataset": {"patch_h": 16, "patch_w": 16},
    "network": {"architecture": "lfnet", "patch": {"rows": 5, "cols": 5, "height": 16,
                "width": 16}, "image": {"channels": 8, "levels": 2}},
    "training": {"epochs": 2, "batch_size": 4},
    "distill": {"passes": 1, "weight": 0.5},
    "stages": ["joint_scratch"],
    "dictionary": {"sampling": {}, "ksvd": {}, "coding": {}},
    "evaluation": {"data": {"random_scenes": 1}, "methods": ["net"], "strides": [5],
                   "noise": [0]}
  })");
}

void read_config(const json& j) { (void)lfnet::pipeline::ExperimentConfig::from_json(j, "config"); }

// The numeric leaves of a JSON object (an architecture's default options), as fields; an empty
// list is a list of whole numbers.
void numeric_leaves(const json& j, const std::string& pointer, std::vector<NumericField>& out) {
  for (const auto& [key, value] : j.items()) {
    std::string p = pointer;
    p += "/";
    p += key;
    if (value.is_object()) {
      numeric_leaves(value, p, out);
    } else if (value.is_number()) {
      out.push_back({p, value.is_number_float(), false});
    } else if (value.is_array() && (value.empty() || value[0].is_number())) {
      out.push_back({p, !value.empty() && value[0].is_number_float(), true});
    }
  }
}

}  // namespace

TEST_CASE("every numeric field of an experiment config has a domain", "[domains]") {
  using namespace lfnet;
  auto fields = fields_of<data::DatasetOptions>("/dataset");
  for (auto& f : fields_of<nn::NetworkOptions>("/network")) fields.push_back(f);
  for (auto& f : fields_of<train::TrainerOptions>("/training")) fields.push_back(f);
  for (auto& f : fields_of<pipeline::DistillConfig>("/distill")) fields.push_back(f);
  for (auto& f : fields_of<pipeline::LightFieldSources>("/data")) fields.push_back(f);
  for (auto& f : fields_of<scene::RandomSceneOptions>("/data/random_options")) fields.push_back(f);
  for (auto& f : fields_of<dict::PatchSamplingOptions>("/dictionary/sampling")) fields.push_back(f);
  for (auto& f : fields_of<dict::KsvdOptions>("/dictionary/ksvd")) fields.push_back(f);
  for (auto& f : fields_of<dict::SparseCodingOptions>("/dictionary/coding")) fields.push_back(f);
  fields.push_back({"/evaluation/strides", false, true});
  fields.push_back({"/evaluation/noise", true, true});
  REQUIRE(fields.size() > 60);
  REQUIRE_NOTHROW(read_config(base_config()));
  check_guarded(unguarded(base_config(), fields, read_config));
}

TEST_CASE("every numeric field of an architecture's own options has a domain", "[domains]") {
  using namespace lfnet;
  int sections = 0;
  for (const auto& name : nn::registered_architectures()) {
    const auto& arch = nn::find_architecture(name);
    if (arch.options_section().empty()) continue;
    INFO(name);
    ++sections;
    auto base = base_config();
    for (const auto& other : nn::registered_architectures()) {
      base["network"].erase(nn::find_architecture(other).options_section());
    }
    base["network"]["architecture"] = name;
    base["network"][arch.options_section()] = arch.default_options();
    std::vector<NumericField> fields;
    numeric_leaves(arch.default_options(), "/network/" + arch.options_section(), fields);
    REQUIRE(fields.size() >= 3);
    REQUIRE_NOTHROW(read_config(base));
    check_guarded(unguarded(base, fields, read_config));
  }
  CHECK(sections >= 3);  // the paper's ("paper"), lfnet's U-Net ("image"), unrolled's
}

TEST_CASE("every numeric field of a learned code has a domain", "[domains]") {
  using namespace lfnet;
  auto base = base_config();
  base["code"] = {{"family", "mask"}, {"period", 2}};
  auto fields = fields_of<nn::LearnedPhiOptions>("/code");
  for (auto& f : fields_of<train::CodeTrainingOptions>("/code")) fields.push_back(f);
  REQUIRE_NOTHROW(read_config(base));
  check_guarded(unguarded(base, fields, read_config));
}

TEST_CASE("every numeric field of a sensor and a camera error has a domain", "[domains]") {
  using namespace lfnet;
  const auto sensor = fields_of<optics::SensorOptions>("");
  check_guarded(unguarded(json::object(), sensor, [](const json& j) {
    (void)optics::SensorOptions::from_json(j, "sensor");
  }));
  const auto error = fields_of<optics::CalibrationError>("");
  check_guarded(unguarded(json::object(), error, [](const json& j) {
    (void)optics::CalibrationError::from_json(j, "--camera-error");
  }));
}

TEST_CASE("every numeric field of the method options has a domain", "[domains]") {
  using namespace lfnet;
  const auto read = [](const json& j) {
    (void)pipeline::method_options_argument(j.dump(), {"dict", "pinv-nlm"});
  };
  const json dict = {{"dict", json::object()}};
  check_guarded(unguarded(dict, fields_of<dict::SparseCodingOptions>("/dict"), read));
  const json nlm = {{"pinv-nlm", {{"denoiser", "nlm"}, {"options", json::object()}}}};
  check_guarded(unguarded(nlm, fields_of<recon::NlmOptions>("/pinv-nlm/options"), read));
  const json opencv = {{"pinv-nlm", {{"denoiser", "opencv-nlm"}, {"options", json::object()}}}};
  check_guarded(unguarded(opencv, fields_of<cv::OpenCvNlmOptions>("/pinv-nlm/options"), read));
}

TEST_CASE("every numeric field of a set entry has a domain", "[domains]") {
  using namespace lfnet;
  test::TempDir tmp;
  const json base = json::parse(R"({"name": "validation", "role": "validation", "about": "a",
    "light_fields": [{"name": "a", "description": "d", "classes": ["plain"], "random": 1}]})");
  const auto path = (tmp / "set.json");
  const auto read = [&](const json& j) {
    std::ofstream(path) << j.dump();
    (void)pipeline::read_set(path);
  };
  REQUIRE_NOTHROW(read(base));
  check_guarded(unguarded(base, fields_of<pipeline::SetEntry>("/light_fields/0"), read));
}
