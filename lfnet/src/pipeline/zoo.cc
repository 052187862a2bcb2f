#include "lfnet/pipeline/zoo.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/phi.h"
#include "lfnet/pipeline/models.h"

#ifndef LFNET_MODELS_DIR
#define LFNET_MODELS_DIR "models"
#endif

namespace fs = std::filesystem;

namespace lfnet::pipeline {

const ZooCard* Zoo::find(const std::string& name) const {
  for (const auto& m : models) {
    if (m.name == name) return &m;
  }
  return nullptr;
}

std::string Zoo::path(const ZooCard& card) const { return (fs::path(dir) / card.file).string(); }

const ZooCard* Zoo::default_for(const std::string& camera, const std::string& colour) const {
  for (const auto& m : models) {
    if (m.card.value("default", false) && m.card.value("camera", "") == camera &&
        m.card.value("colour", "") == colour) {
      return &m;
    }
  }
  return nullptr;
}

std::string zoo_dir() {
  if (const char* env = std::getenv("LFNET_MODELS"); env != nullptr && *env != '\0') return env;
  std::error_code ec;
  if (fs::is_regular_file("models/zoo.json", ec)) return "models";
  return LFNET_MODELS_DIR;
}

Zoo read_zoo(const std::string& dir) {
  const auto path = (fs::path(dir) / "zoo.json").string();
  std::error_code ec;
  LFNET_CHECK_AS(IoError, fs::is_regular_file(path, ec), "the model zoo ", path,
                 " is missing (LFNET_MODELS names another folder)");
  const auto doc = read_json_file(path);
  LFNET_CHECK_AS(ConfigError, doc.is_object() && doc.contains("models") && doc["models"].is_array(),
                 path, ": expected an object with a list \"models\"");
  Zoo zoo;
  zoo.dir = dir;
  for (size_t i = 0; i < doc["models"].size(); ++i) {
    const auto& c = doc["models"][i];
    const std::string at = path + ":$.models[" + std::to_string(i) + "]";
    LFNET_CHECK_AS(ConfigError,
                   c.is_object() && c.value("name", "") != "" && c.value("file", "") != "", at,
                   ": a card needs a name and a file");
    LFNET_CHECK_AS(ConfigError, zoo.find(c["name"]) == nullptr, at, ": the name ",
                   c["name"].get<std::string>(), " appears twice");
    zoo.models.push_back({c["name"], c["file"], c});
  }
  return zoo;
}

std::string resolve_model_name(const std::string& text) {
  std::error_code ec;
  if (text.empty() || fs::exists(text, ec) || text.find('/') != std::string::npos) return text;
  try {
    const Zoo zoo = read_zoo();
    if (const auto* m = zoo.find(text)) return zoo.path(*m);
  } catch (const Error&) {
    // Not a zoo name after all: the command reports the missing file as it would.
  }
  return text;
}

SensorCamera sensor_camera(const std::string& sensor, const std::string& phi,
                           const std::string& cfa) {
  SensorCamera c;
  try {
    std::error_code ec;
    optics::PhiSpec spec;
    if (fs::is_directory(sensor, ec)) {
      const auto meta = read_json_file((fs::path(sensor) / "sensor.json").string());
      spec = optics::PhiSpec::from_json(meta.at("phi"), sensor + "/sensor.json:$.phi");
      if (meta.contains("cfa")) {
        c.colour = optics::ColourFilterArray::from_json(meta["cfa"], sensor + "/sensor.json:$.cfa")
                       .pattern();
      }
    } else if (!phi.empty()) {
      spec = phi_from_argument(phi);
      if (const auto given = optics::resolve_cfa(cfa, spec.to_json())) c.colour = given->pattern();
    } else {
      return c;
    }
    c.camera = spec.label();
  } catch (const Error&) {
    c.camera.clear();
  } catch (const nlohmann::json::exception&) {
    c.camera.clear();
  }
  return c;
}

ZooDefault zoo_default_model(const std::string& sensor, const std::string& phi,
                             const std::string& cfa) {
  const auto c = sensor_camera(sensor, phi, cfa);
  ZooDefault d;
  d.camera = c.camera;
  d.colour = c.colour;
  if (d.camera.empty()) return d;
  try {
    const Zoo zoo = read_zoo();
    if (const auto* m = zoo.default_for(d.camera, d.colour)) {
      d.name = m->name;
      d.path = zoo.path(*m);
    }
  } catch (const Error&) {
    // No default: the reconstruction reads the same files and reports what is wrong with them.
  }
  return d;
}

namespace {

struct FileFacts {
  std::string parameters, megabytes;
};

FileFacts file_facts(const Zoo& zoo, const ZooCard& m) {
  FileFacts f;
  const auto path = zoo.path(m);
  std::error_code ec;
  if (!fs::exists(path, ec)) return {"missing", "missing"};
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.1f", static_cast<double>(fs::file_size(path, ec)) / 1e6);
  f.megabytes = buf;
  const auto kind = model_file_kind(path);
  if (kind != ModelFileKind::kCheckpoint && kind != ModelFileKind::kNoiseSwitch) return f;
  auto model = load_model(path, true);
  int64_t n = 0;
  for (const auto& p : model.net->parameters()) n += p.numel();
  if (model.noise_switch()) {
    for (const auto& p : model.noisy->parameters()) n += p.numel();
    // The switch's members' files count too.
    const double mb = static_cast<double>(fs::file_size(model.quiet_path, ec) +
                                          fs::file_size(model.noisy_path, ec)) /
                      1e6;
    std::snprintf(buf, sizeof buf, "%.1f", mb);
    f.megabytes = buf;
  }
  std::snprintf(buf, sizeof buf, "%.2fM", static_cast<double>(n) / 1e6);
  f.parameters = buf;
  return f;
}

std::string worst(const nlohmann::json& card, const char* role) {
  if (!card.contains("measured") || !card["measured"].contains(role)) return "";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%+.2f",
                card["measured"][role].value("worst_margin_over_pinv_db", 0.0));
  return buf;
}

}  // namespace

std::string zoo_table(const Zoo& zoo) {
  std::ostringstream out;
  char line[512];
  int width = 30;  // the name column fits the longest name
  for (const auto& m : zoo.models) width = std::max(width, static_cast<int>(m.name.size()));
  std::snprintf(line, sizeof line, "%-*s %-10s %-6s %-10s %-7s %-5s %-6s %-6s %s\n", width, "name",
                "camera", "colour", "params", "MB", "val", "test", "def", "use");
  out << line;
  for (const auto& m : zoo.models) {
    const auto f = file_facts(zoo, m);
    // A learned code's camera is in its file, a dictionary's is any: one word each.
    std::string camera = m.card.value("camera", "");
    if (camera.rfind("learned", 0) == 0) camera = "learned";
    if (camera.rfind("any", 0) == 0) camera = "any";
    std::snprintf(line, sizeof line, "%-*s %-10s %-6s %-10s %-7s %-5s %-6s %-6s %s\n", width,
                  m.name.c_str(), camera.c_str(), m.card.value("colour", "").c_str(),
                  f.parameters.c_str(), f.megabytes.c_str(), worst(m.card, "validation").c_str(),
                  worst(m.card, "test").c_str(), m.card.value("default", false) ? "yes" : "",
                  m.card.value("use", "").c_str());
    out << line;
  }
  out << "\nval, test: the worst margin over pinv in dB on the validation and test sets "
         "(docs/protocol.md); def: the default for its camera.\n";
  return out.str();
}

std::string zoo_card(const Zoo& zoo, const std::string& name) {
  const auto* m = zoo.find(name);
  if (m == nullptr) {
    std::string names;
    for (const auto& c : zoo.models) names += (names.empty() ? "" : ", ") + c.name;
    throw ConfigError("no model '" + name + "' in the zoo (" + names + ")");
  }
  auto card = m->card;
  const auto f = file_facts(zoo, *m);
  card["path"] = zoo.path(*m);
  if (!f.parameters.empty()) card["parameters"] = f.parameters;
  card["megabytes"] = f.megabytes;
  return card.dump(2) + "\n";
}

}  // namespace lfnet::pipeline
