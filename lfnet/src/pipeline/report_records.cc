#include "report_records.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/pipeline/figures.h"
#include "lfnet/pipeline/sets.h"
#include "lfnet/recon/method_registry.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline::report {

int method_rank(const std::string& m) {
  static const std::vector<std::string> order = recon::registered_methods();
  auto it = std::find(order.begin(), order.end(), m);
  return static_cast<int>(it - order.begin());
}

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), f, v);
  return buf;
}

double number(const nlohmann::json& r, const char* key, double fallback) {
  return r.contains(key) && r[key].is_number() ? r[key].get<double>() : fallback;
}

std::string phi_name(const nlohmann::json& r) {
  return r.contains("phi") && r["phi"].is_object() ? r["phi"].value("name", "?") : "?";
}

double noise_level(const nlohmann::json& r) {
  return number(r, "equivalent_sigma", number(r, "noise_sigma", 0.0));
}

std::string setting(const nlohmann::json& r, const std::string& key) {
  if (key == "method") return r.value("method", "");
  if (key == "phi") return phi_name(r);
  if (key == "n") return std::to_string(r.value("measurements", 0));
  if (key == "stride") {
    // A whole-image reconstruction (the lfnet architecture) has no patches, so no stride.
    return r.value("whole_image", false) ? "whole image" : std::to_string(r.value("stride", 0));
  }
  if (key == "mode") return r.value("mode", "");
  if (key == "noise") return fmt("%.3g", noise_level(r));
  if (key == "light_field") return r.value("light_field", "");
  if (key == "scale") return r.value("scale", "");
  if (key == "variant") return r.value("variant", "");
  if (key == "camera_error") {
    // The fields of the camera's error that are not 0 ("" for a camera that is its Phi).
    std::string text;
    if (!r.contains("camera_error") && !r.value("flat_field", false)) return text;
    for (const auto& [field, value] : r["camera_error"].items()) {
      if (!value.is_number() || value.get<double>() == 0) continue;
      text += (text.empty() ? "" : ", ") + field + " " + fmt("%+g", value.get<double>());
    }
    // Corrected by the camera's flat field (--flat-field).
    if (r.value("flat_field", false)) text += std::string(text.empty() ? "" : ", ") + "flat field";
    return text;
  }
  return "";
}

double as_number(const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  return end == text.c_str() ? INFINITY : v;
}

const std::vector<std::string> kSettings = {"light_field",  "variant", "phi",  "n",     "noise",
                                            "camera_error", "stride",  "mode", "method"};

bool on_paper_scene(const std::string& light_field) {
  return light_field.rfind(kPaperScene, 0) == 0;
}

std::string aperture(const std::string& light_field) {
  const auto at = light_field.rfind("_ap");
  if (!on_paper_scene(light_field) || at == std::string::npos) return "";
  return light_field.substr(at + 3);
}

std::string scene_label(const std::string& light_field) {
  const auto cm = aperture(light_field);
  return cm.empty() ? light_field : "aperture " + cm + " cm";
}

std::vector<Section> read_sections(const std::string& dir) {
  LFNET_CHECK_AS(IoError, fs::is_directory(dir), dir, " is not a folder of result sections");
  std::vector<Section> sections;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (!entry.is_directory() || !fs::exists(entry.path() / "section.json")) continue;
    Section s;
    s.name = entry.path().filename().string();
    s.meta = read_json_file((entry.path() / "section.json").string());
    const fs::path records = entry.path() / "records.jsonl";
    if (fs::exists(records)) s.records = read_jsonl(records.string());
    sections.push_back(std::move(s));
  }
  std::sort(sections.begin(), sections.end(), [](const Section& a, const Section& b) {
    const int oa = a.meta.value("order", 1000), ob = b.meta.value("order", 1000);
    return oa != ob ? oa < ob : a.name < b.name;
  });
  LFNET_CHECK_AS(IoError, !sections.empty(), "no section (a folder with section.json) in ", dir);
  return sections;
}

bool matches(const nlohmann::json& r, const nlohmann::json& selector) {
  for (auto it = selector.begin(); it != selector.end(); ++it) {
    if (std::find(kSettings.begin(), kSettings.end(), it.key()) == kSettings.end()) continue;
    const std::string want = it->is_string()       ? it->get<std::string>()
                             : it.key() == "noise" ? fmt("%g", it->get<double>())
                                                   : it->dump();
    if (setting(r, it.key()) != want) return false;
  }
  return true;
}

const nlohmann::json* paper_entry(const Section& s, const nlohmann::json& r) {
  if (!s.meta.contains("paper") || !on_paper_scene(r.value("light_field", ""))) return nullptr;
  for (const auto& p : s.meta["paper"]) {
    if (matches(r, p)) return &p;
  }
  return nullptr;
}

const nlohmann::json* find_record(const Section& s, const nlohmann::json& selector) {
  for (const auto& r : s.records) {
    if (matches(r, selector)) return &r;
  }
  return nullptr;
}

std::vector<std::string> light_fields(const Section& s) {
  std::set<std::string> names;
  for (const auto& r : s.records) names.insert(r.value("light_field", ""));
  std::vector<std::string> out(names.begin(), names.end());
  std::stable_sort(out.begin(), out.end(), [](const std::string& a, const std::string& b) {
    if (on_paper_scene(a) != on_paper_scene(b)) return on_paper_scene(a);
    return on_paper_scene(a) ? as_number(aperture(a)) < as_number(aperture(b)) : a < b;
  });
  return out;
}

std::vector<GapClaim> gap_claims(const Section& s) {
  std::vector<GapClaim> out;
  if (!s.meta.contains("gaps")) return out;
  for (const auto& lf : light_fields(s)) {
    for (const auto& g : s.meta["gaps"]) {
      GapClaim c{s.meta.value("title", s.name), scene_label(lf), g.value("claim", ""),
                 g.value("source", "")};
      const auto& p = g.at("paper_db");
      c.low = p.is_array() ? p.at(0).get<double>() : p.get<double>();
      c.high = p.is_array() ? p.at(1).get<double>() : c.low;
      auto a = g.at("a"), b = g.at("b");
      a["light_field"] = lf;
      b["light_field"] = lf;
      const auto* ra = find_record(s, a);
      const auto* rb = find_record(s, b);
      if (ra && rb) c.ours = number(*ra, "psnr_db") - number(*rb, "psnr_db");
      out.push_back(c);
    }
  }
  return out;
}

std::string gap_verdict(const GapClaim& c) {
  if (std::isnan(c.ours)) return "not measured (records missing)";
  if (c.ours >= c.low - kGapTolerance) return "yes";
  const std::string by = " (" + fmt("%+.2f dB", c.ours - c.low) + ")";
  if (c.low > 0 && c.ours > 0) return "direction only" + by;
  return "no" + by;
}

}  // namespace lfnet::pipeline::report
