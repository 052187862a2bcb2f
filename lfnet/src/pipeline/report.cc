// The results report (pipeline/report.h): every table lists the simulation mode and warns when
// the no-parallax baseline is missing; figures are drawn by scripts/figures.py.
#include "lfnet/pipeline/report.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <map>
#include <set>
#include <sstream>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/metrics.h"
#include "lfnet/core/output.h"
#include "lfnet/eval/evaluate.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/viewer.h"
#include "lfnet/pipeline/figures.h"
#include "lfnet/pipeline/sets.h"
#include "lfnet/recon/method_registry.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

namespace {

struct Section {
  std::string name;  // folder name
  nlohmann::json meta;
  std::vector<nlohmann::json> records;
};

const std::vector<std::string> kMethodOrder = recon::registered_methods();

int method_rank(const std::string& m) {
  auto it = std::find(kMethodOrder.begin(), kMethodOrder.end(), m);
  return static_cast<int>(it - kMethodOrder.begin());
}

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), f, v);
  return buf;
}

double number(const nlohmann::json& r, const char* key, double fallback = NAN) {
  return r.contains(key) && r[key].is_number() ? r[key].get<double>() : fallback;
}

std::string phi_name(const nlohmann::json& r) {
  return r.contains("phi") && r["phi"].is_object() ? r["phi"].value("name", "?") : "?";
}

// A record's noise: its Gaussian sigma, or with shot and read noise the Gaussian sigma of the
// same variance (docs/acquisition.md).
double noise_level(const nlohmann::json& r) {
  return number(r, "equivalent_sigma", number(r, "noise_sigma", 0.0));
}

// The value of a setting of a record, as text: method, phi, n, stride, mode, noise,
// light_field, scale.
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

// A numeric setting's text as a number; text that is none ("whole image") sorts last.
double as_number(const std::string& text) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  return end == text.c_str() ? INFINITY : v;
}

const std::vector<std::string> kSettings = {"light_field",  "variant", "phi",  "n",     "noise",
                                            "camera_error", "stride",  "mode", "method"};

// The paper's own test scene, MIT "Dragons and Bunnies" at four apertures (docs/results.md,
// "The paper's scene"): the paper's figures are compared on it alone, at each aperture.
constexpr const char* kPaperScene = "mit_dragons_bunnies";
// The front page's scene: the paper's at the 5 cm aperture.
constexpr const char* kFrontLightField = "mit_dragons_bunnies_5x5_ap5";

bool on_paper_scene(const std::string& light_field) {
  return light_field.rfind(kPaperScene, 0) == 0;
}

// The aperture in cm of the paper's scene ("5" of a folder name ending in _ap5), "" for other
// light fields.
std::string aperture(const std::string& light_field) {
  const auto at = light_field.rfind("_ap");
  if (!on_paper_scene(light_field) || at == std::string::npos) return "";
  return light_field.substr(at + 3);
}

// "aperture 5 cm" for the paper's scene at that aperture, the light field's name otherwise.
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

// Whether a record has every setting a selector names (keys other than settings are ignored).
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

// The paper entry of a section that matches a record: every setting it names must agree.
const nlohmann::json* paper_entry(const Section& s, const nlohmann::json& r) {
  if (!s.meta.contains("paper") || !on_paper_scene(r.value("light_field", ""))) return nullptr;
  for (const auto& p : s.meta["paper"]) {
    if (matches(r, p)) return &p;
  }
  return nullptr;
}

// The first record of a section that a selector matches.
const nlohmann::json* find_record(const Section& s, const nlohmann::json& selector) {
  for (const auto& r : s.records) {
    if (matches(r, selector)) return &r;
  }
  return nullptr;
}

// A claim of the paper about a difference: "a" is better than "b" by paper_db (a number, or
// [low, high]). Ours is psnr(a) - psnr(b) from the section's records.
struct GapClaim {
  std::string section, scene, claim, source;
  double low = NAN, high = NAN, ours = NAN;
};

// The light fields of a section's records: the paper's scene first (by aperture), then others.
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

// Each claim on each light field of the section: differences on one scene compare across
// scenes, so every scene gets its verdict.
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

// Reproduced: ours is at least the paper's (lower) gap, less 0.1 dB. A claimed gain that we
// measure as a smaller gain is "direction only"; anything else (a loss, a larger drop) is "no".
constexpr double kGapTolerance = 0.1;
// A figure of the paper is reproduced when ours is at most this far below it.
constexpr double kPsnrTolerance = 0.5;

std::string gap_verdict(const GapClaim& c) {
  if (std::isnan(c.ours)) return "not measured (records missing)";
  if (c.ours >= c.low - kGapTolerance) return "yes";
  const std::string by = " (" + fmt("%+.2f dB", c.ours - c.low) + ")";
  if (c.low > 0 && c.ours > 0) return "direction only" + by;
  return "no" + by;
}

// One paper claim against ours, for the summary at the end.
struct Claim {
  std::string section, scene, setting;
  double paper_psnr = NAN, ours_psnr = NAN, paper_s = NAN, ours_s = NAN;
  std::string source;
};

// Records in table order: by their settings, then by method.
std::vector<nlohmann::json> table_order(std::vector<nlohmann::json> rows) {
  std::sort(rows.begin(), rows.end(), [](const nlohmann::json& a, const nlohmann::json& b) {
    for (const auto& k : kSettings) {
      if (k == "method") continue;
      const auto va = setting(a, k), vb = setting(b, k);
      if (va != vb) {
        if (k == "n" || k == "stride" || k == "noise") return as_number(va) < as_number(vb);
        return va < vb;
      }
    }
    return method_rank(a.value("method", "")) < method_rank(b.value("method", ""));
  });
  return rows;
}

// The table of a section's records: a column for each setting that varies (and always the
// method and the mode), the scores, then the columns that some record fills.
class RecordTable {
 public:
  RecordTable(const Section& s, std::vector<Claim>& claims)
      : s_(s), claims_(claims), rows_(table_order(s.records)), settings_{"method"} {
    for (const auto& k : kSettings) {
      std::set<std::string> values;
      for (const auto& r : rows_) values.insert(setting(r, k));
      if (k != "method" && k != "mode" && values.size() > 1) settings_.push_back(k);
    }
    settings_.push_back("mode");
    add_result_columns();
  }

  std::string markdown() const {
    std::ostringstream md;
    md << "|";
    for (const auto& c : settings_) md << " " << setting_header(c) << " |";
    for (const auto& c : results_) md << " " << c.header << " |";
    md << "\n|";
    for (size_t i = 0; i < settings_.size(); ++i) md << "---|";
    // Numbers right-aligned; text (the choice) left-aligned after them.
    for (const auto& c : results_) {
      for (int i = 0; i < c.width; ++i) md << (c.text ? "---|" : "---:|");
    }
    md << "\n";
    int64_t test_choices = 0;
    for (const auto& r : rows_) {
      md << "|";
      for (const auto& c : settings_) {
        const auto value = setting(r, c);
        md << " " << (c == "camera_error" && value.empty() ? "none" : value) << " |";
      }
      for (const auto& c : results_) md << " " << c.cell(r) << " |";
      md << "\n";
      test_choices += r.contains("choice") && record_role(r) == "test";
      add_claim(r);
    }
    if (test_choices > 0) {
      md << "\n**" << test_choices
         << " record(s) here decided a choice on a light field of the test set**: choices are "
            "made on the validation set, and the test set is only reported (docs/protocol.md).\n";
    }
    bool baseline = false;
    for (const auto& r : rows_) baseline |= r.value("method", "") == "no-parallax";
    if (!baseline) md << "\n*These records have no `no-parallax` baseline.*\n";
    return md.str();
  }

 private:
  struct Column {
    std::string header;
    std::function<std::string(const nlohmann::json&)> cell;
    int width = 1;      // markdown columns it spans (the paper's PSNR and seconds: 2)
    bool text = false;  // left-aligned
  };

  static std::string setting_header(const std::string& c) {
    return c == "n"              ? "N"
           : c == "light_field"  ? "light field"
           : c == "camera_error" ? "camera error"
                                 : c;
  }

  bool any(const std::string& key) const {
    return std::any_of(rows_.begin(), rows_.end(),
                       [&](const nlohmann::json& r) { return r.contains(key); });
  }

  static double psnr_of(const nlohmann::json& r) { return number(r, "psnr_db", INFINITY); }

  // A record of a camera whose Phi is off: the PSNR of the same record (every other setting
  // equal) of the nominal camera.
  double nominal_psnr(const nlohmann::json& r) const {
    if (setting(r, "camera_error").empty()) return NAN;
    for (const auto& other : rows_) {
      if (!setting(other, "camera_error").empty()) continue;
      bool same = true;
      for (const auto& k : kSettings) {
        if (k != "camera_error" && setting(other, k) != setting(r, k)) same = false;
      }
      if (same) return number(other, "psnr_db");
    }
    return NAN;
  }

  void add_result_columns() {
    const auto optional = [](double v, const char* format) {
      return std::isfinite(v) ? fmt(format, v) : std::string();
    };
    results_.push_back({"PSNR dB", [](const nlohmann::json& r) {
                          const double psnr = psnr_of(r);
                          return std::isfinite(psnr) ? fmt("%.2f", psnr) : std::string("inf");
                        }});
    results_.push_back(
        {"SSIM", [](const nlohmann::json& r) { return fmt("%.3f", number(r, "ssim")); }});
    results_.push_back(
        {"seconds", [](const nlohmann::json& r) { return fmt("%.2f", number(r, "seconds")); }});
    if (any("luma_psnr_db")) {  // colour records: the luma's PSNR beside the colour one
      results_.push_back({"luma PSNR dB", [=](const nlohmann::json& r) {
                            return optional(number(r, "luma_psnr_db", NAN), "%.2f");
                          }});
    }
    // What the camera's error costs against the nominal camera.
    if (std::find(settings_.begin(), settings_.end(), "camera_error") != settings_.end()) {
      results_.push_back({"cost dB", [this](const nlohmann::json& r) {
                            const double nominal = nominal_psnr(r);
                            return std::isfinite(nominal) ? fmt("%.2f", nominal - psnr_of(r))
                                                          : std::string();
                          }});
    }
    if (any("noise_sigma_estimated")) {  // noise-blind records: the sigma they estimated
      results_.push_back({"estimated sigma", [=](const nlohmann::json& r) {
                            return r.contains("noise_sigma_estimated")
                                       ? fmt("%.4f", number(r, "noise_sigma_estimated"))
                                       : std::string();
                          }});
    }
    if (any("camera_error_estimated")) {  // self-calibrated records: the shift they estimated
      results_.push_back({"estimated shift", [](const nlohmann::json& r) { return shift(r); }});
    }
    if (any("training_seconds")) {
      results_.push_back({"training s", [](const nlohmann::json& r) {
                            return r.contains("training_seconds")
                                       ? fmt("%.0f", number(r, "training_seconds"))
                                       : std::string();
                          }});
    }
    add_paper_column();
    if (any("choice")) {  // records that decided something; one made on the test set is marked
      results_.push_back({"choice",
                          [](const nlohmann::json& r) {
                            const std::string choice = r.value("choice", "");
                            return choice.empty() ? std::string()
                                   : record_role(r) == "test"
                                       ? "**made on the test set:** " + choice
                                       : choice;
                          },
                          1, true});
    }
  }

  // The views along U (and along V when that was found too).
  static std::string shift(const nlohmann::json& r) {
    if (!r.contains("camera_error_estimated")) return "";
    const auto& e = r["camera_error_estimated"];
    std::string out = fmt("U %.3f", e.value("angular_shift_u", 0.0));
    const double v = e.value("angular_shift_v", 0.0);
    if (v != 0) out += fmt(", V %.3f", v);
    return out;
  }

  static std::pair<double, double> paper_figures(const nlohmann::json& p) {
    return {p.contains("psnr_db") ? p["psnr_db"].get<double>() : NAN,
            p.contains("seconds") ? p["seconds"].get<double>() : NAN};
  }

  void add_paper_column() {
    const bool has_paper = std::any_of(rows_.begin(), rows_.end(), [&](const nlohmann::json& r) {
      return paper_entry(s_, r) != nullptr;
    });
    if (!has_paper) return;
    results_.push_back({"paper PSNR dB | paper seconds",
                        [this](const nlohmann::json& r) {
                          const auto* p = paper_entry(s_, r);
                          if (!p) return std::string("|");
                          const auto [pp, ps] = paper_figures(*p);
                          return (std::isnan(pp) ? "" : fmt("%.2f", pp)) + " | " +
                                 (std::isnan(ps) ? "" : fmt("%g", ps));
                        },
                        2});
  }

  // A record that the paper has a figure for is a claim of the summary at the end.
  void add_claim(const nlohmann::json& r) const {
    const auto* p = paper_entry(s_, r);
    if (!p) return;
    const auto [pp, ps] = paper_figures(*p);
    std::string what;
    for (const auto& c : settings_) {
      if (c != "light_field") what += (what.empty() ? "" : ", ") + c + " " + setting(r, c);
    }
    claims_.push_back({s_.meta.value("title", s_.name), scene_label(r.value("light_field", "")),
                       what, pp, psnr_of(r), ps, number(r, "seconds"), p->value("source", "")});
  }

  const Section& s_;
  std::vector<Claim>& claims_;
  std::vector<nlohmann::json> rows_;
  std::vector<std::string> settings_;  // the setting columns
  std::vector<Column> results_;        // the columns after them
};

std::string markdown_table(const Section& s, std::vector<Claim>& claims) {
  return RecordTable(s, claims).markdown();
}

// net minus no-parallax, dict and pinv for every group of records that differ only in method.
std::string margins(const Section& s) {
  std::map<std::string, std::map<std::string, double>> groups;
  for (const auto& r : s.records) {
    std::string key;
    for (const auto& k : kSettings) {
      if (k != "method" && !setting(r, k).empty()) {
        key += (key.empty() ? "" : ", ") + (k == "n" ? std::string("N") : k) + " " + setting(r, k);
      }
    }
    groups[key][r.value("method", "")] = number(r, "psnr_db");
  }
  std::ostringstream md;
  for (const auto& [key, by_method] : groups) {
    if (!by_method.count("net")) continue;
    std::string line;
    for (const char* other : {"no-parallax", "dict", "pinv"}) {
      if (!by_method.count(other)) continue;
      line += (line.empty() ? "" : ", ") + std::string("net - ") + other + " = " +
              fmt("%+.2f dB", by_method.at("net") - by_method.at(other));
    }
    if (!line.empty()) md << "- " << key << ": " << line << "\n";
  }
  return md.str();
}

// The value of a sweep's setting in a record, as a number.
double sweep_value(const nlohmann::json& r, const std::string& key) {
  if (key == "noise") return noise_level(r);
  if (key == "n") return number(r, "measurements", 0.0);
  return number(r, key.c_str(), 0.0);
}

// A "sweep" figure of a section: PSNR against one setting ("n", "stride" or "noise"), a series
// per method (and per other setting that varies), the paper's numbers as series of their own.
nlohmann::json sweep_spec(const Section& whole, const nlohmann::json& sweep) {
  const std::string key = sweep.at("x").get<std::string>();
  // "light_field": the sweep of one light field only (the section's table keeps them all).
  const std::string only = sweep.value("light_field", "");
  Section s = whole;
  if (!only.empty()) {
    s.records.clear();
    for (const auto& r : whole.records) {
      if (r.value("light_field", "") == only) s.records.push_back(r);
    }
  }
  std::map<std::string, nlohmann::json> series;
  std::vector<std::string> order;
  auto add_point = [&](const std::string& label, const std::string& method, const char* kind,
                       double x, double y) {
    if (!series.count(label)) {
      order.push_back(label);
      series[label] = {{"label", label}, {"method", method}, {"kind", kind}, {"x", {}}, {"y", {}}};
    }
    series[label]["x"].push_back(x);
    series[label]["y"].push_back(y);
  };
  // Other settings that vary name the series (e.g. "net, mode per_patch").
  std::vector<std::string> varying;
  for (const auto& k : kSettings) {
    if (k == key || k == "method" || k == "variant") continue;
    std::set<std::string> values;
    for (const auto& r : s.records) values.insert(setting(r, k));
    if (values.size() > 1) varying.push_back(k);
  }
  auto rows = s.records;
  std::stable_sort(rows.begin(), rows.end(), [&](const auto& x, const auto& y) {
    return sweep_value(x, key) < sweep_value(y, key);
  });
  for (const auto& r : rows) {
    const double y = number(r, "psnr_db");
    if (!std::isfinite(y)) continue;
    if (key == "stride" && r.value("whole_image", false)) continue;  // no stride to plot at
    const std::string method = r.value("method", "");
    std::string label = method;
    if (!r.value("variant", "").empty()) label += " (" + r.value("variant", "") + ")";
    for (const auto& k : varying) {
      label += ", " + (k == "light_field" ? scene_label(setting(r, k)) : k + " " + setting(r, k));
    }
    add_point(label, method, recon::is_baseline(method) ? "baseline" : "ours", sweep_value(r, key),
              y);
  }
  if (s.meta.contains("paper")) {
    for (const auto& p : s.meta["paper"]) {
      if (!p.contains(key) || !p.contains("psnr_db")) continue;
      const double x = p[key].get<double>();
      add_point("paper: " + p.value("method", "net"), p.value("method", "net"), "paper", x,
                p["psnr_db"].get<double>());
    }
  }
  auto list = nlohmann::json::array();
  for (const auto& label : order) {
    if (series[label]["x"].size() >= 2) list.push_back(series[label]);
  }
  return {{"kind", "sweep"},
          {"stem", s.name + "_sweep"},
          {"title", s.meta.value("title", s.name) + ": PSNR against " + sweep.value("label", key) +
                        (only.empty() ? "" : ", " + scene_label(only))},
          {"xlabel", sweep.value("label", key)},
          {"xlog", sweep.value("log", false)},
          {"series", list}};
}

// Markdown that shows a figure and links its vector twin.
std::string figure_markdown(const std::string& alt, const std::string& link,
                            const std::string& stem) {
  return "![" + alt + "](" + link + "/" + stem + ".png) ([SVG](" + link + "/" + stem + ".svg))";
}

// The "views" figure of a section's pictures: centre-view crops and horizontal EPIs of the truth
// (first) and each reconstruction, with PSNR over all views in the titles.
nlohmann::json pictures_spec(const std::vector<LightField>& lfs,
                             const std::vector<std::string>& titles, const std::string& stem,
                             const FigureSet& figure_set) {
  constexpr int64_t kCrop = 160, kEpiScale = 8;
  auto panels = nlohmann::json::array();
  for (size_t i = 0; i < lfs.size(); ++i) {
    const auto& lf = lfs[i];
    const int64_t h = std::min(kCrop, lf.height()), w = std::min(kCrop, lf.width());
    const int64_t y0 = (lf.height() - h) / 2, x0 = (lf.width() - w) / 2;
    const auto view =
        lf.view(lf.rows() / 2, lf.cols() / 2)[0].slice(0, y0, y0 + h).slice(1, x0, x0 + w);
    const auto epi = io::horizontal_epi(lf, -1, kEpiScale)[0].slice(1, x0, x0 + w);
    const std::string name = stem + "_" + std::to_string(i);
    nlohmann::json panel = {{"label", titles[i]},
                            {"view", figure_set.image(name + "_view", view)},
                            {"epi", figure_set.image(name + "_epi", epi)}};
    if (i > 0 && lf.data().sizes() == lfs[0].data().sizes()) panel["psnr_db"] = psnr(lf, lfs[0]);
    panels.push_back(panel);
  }
  return {{"kind", "views"},
          {"stem", stem},
          {"title", "Centre views (160 px crops), horizontal EPIs and |error| of the centre view"},
          {"panels", panels}};
}

// A viewer page (io/viewer.h) of the first reconstruction against the truth (lfs[0]), on the
// central `crop` x `crop` pixels so the page stays small enough to keep beside the report.
void write_section_viewer(const std::vector<LightField>& lfs,
                          const std::vector<std::string>& titles, const std::string& path,
                          int64_t crop = 256) {
  const size_t k = lfs.size() > 1 ? 1 : 0;
  auto central = [&](const LightField& lf) {
    const int64_t h = std::min(crop, lf.height()), w = std::min(crop, lf.width());
    const int64_t y0 = (lf.height() - h) / 2, x0 = (lf.width() - w) / 2;
    return LightField(lf.data().slice(axis::kH, y0, y0 + h).slice(axis::kW, x0, x0 + w));
  };
  const auto truth = central(lfs[0]), estimate = central(lfs[k]);
  io::ViewerPage page;
  page.title = titles[k] + " against the truth (central " + std::to_string(estimate.height()) +
               " x " + std::to_string(estimate.width()) + " pixels)";
  page.truth = truth;
  page.record = eval::score(estimate, truth);  // PSNR, SSIM and per-view PSNR, as evaluate's
  page.record["method"] = titles[k];
  io::write_viewer(estimate, path, page);
}

// The front page: what accuracy costs in time on the paper's scene at 5 cm (sensor mode, no
// noise), every method and architecture of every section once, as a table and the Pareto plot
// against `time`. Empty when no section measured that scene.
std::string front_page(const std::vector<Section>& sections, ParetoTime time, FigureSet& figure_set,
                       const std::string& figures_link) {
  std::vector<nlohmann::json> rows;
  std::set<std::string> seen;
  for (const auto& s : sections) {
    for (const auto& r : s.records) {
      if (r.value("light_field", "") != kFrontLightField || r.value("mode", "") != "sensor" ||
          noise_level(r) != 0 || !std::isfinite(number(r, "psnr_db")))
        continue;
      // One row per reconstruction: a model measured in two sections (or a baseline of one
      // camera) is listed once, under the first section's variant; no-parallax, which sees no
      // camera, once.
      const std::string method = r.value("method", "");
      const bool camera_free = recon::find_method(method).needs() == recon::MethodNeeds::kTruth;
      const std::string key = camera_free
                                  ? method
                                  : method + "|" +
                                        (recon::is_baseline(method) ? phi_name(r) + setting(r, "n")
                                                                    : r.value("model", "")) +
                                        "|" + setting(r, "stride") + "|" +
                                        r.value("self_ensemble_passes", nlohmann::json(0)).dump() +
                                        "|" + r.value("precision", "");
      if (seen.insert(key).second) rows.push_back(r);
    }
  }
  if (rows.empty()) return "";
  const bool end_to_end = time == ParetoTime::kEndToEnd;
  const char* time_key = end_to_end ? "end_to_end_seconds" : "seconds";
  std::vector<ParetoPoint> points;
  std::vector<size_t> plotted;  // the row of each point
  for (size_t i = 0; i < rows.size(); ++i) {
    if (!std::isfinite(number(rows[i], time_key))) continue;  // older records lack end to end
    auto p = pareto_point(rows[i]);
    p.seconds = number(rows[i], time_key);
    points.push_back(p);
    plotted.push_back(i);
  }
  mark_pareto_front(points);
  std::vector<bool> on_front(rows.size(), false);
  for (size_t k = 0; k < points.size(); ++k) on_front[plotted[k]] = points[k].front;
  std::vector<size_t> order(rows.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return number(rows[a], time_key, INFINITY) < number(rows[b], time_key, INFINITY);
  });
  const std::string what = end_to_end ? "end-to-end time" : "reconstruction time";
  figure_set.add(pareto_spec(points,
                             "What accuracy costs in time: the paper's scene, aperture 5 cm "
                             "(sensor mode, no noise)",
                             end_to_end ? "end-to-end time of the command (s, log scale)"
                                        : "reconstruction time (s, log scale)"));
  std::ostringstream md;
  md << "## What accuracy costs in time, on the paper's scene\n\n"
     << "Every method and architecture below on the paper's own test scene, Dragons and Bunnies "
        "at the 5 cm aperture (593 x 840 x 5 x 5), `sensor` mode, no noise, against the "
     << what << " (`lfnet report --pareto-time`): \"seconds\" is the reconstruction alone, "
     << "\"end to end\" the whole `lfnet evaluate` command as its user waits for it (loading "
        "included). The other apertures are in the sections below (\"The paper's scene\").\n\n"
     << figure_markdown("PSNR against seconds", figures_link, "pareto") << "\n\n"
     << "| method | variant | N | stride | PSNR dB | SSIM | seconds | end to end s | on the front "
        "|\n|---|---|---:|---|---:|---:|---:|---:|---|\n";
  for (const size_t i : order) {
    const auto& r = rows[i];
    // A baseline's variant names the model it was measured beside, not the baseline.
    const std::string method = r.value("method", "");
    const bool camera_free = recon::find_method(method).needs() == recon::MethodNeeds::kTruth;
    md << "| " << method << " | " << (recon::is_baseline(method) ? "" : r.value("variant", ""))
       << " | " << (camera_free ? "" : setting(r, "n")) << " | "
       << (camera_free ? "" : setting(r, "stride")) << " | " << fmt("%.2f", number(r, "psnr_db"))
       << " | " << fmt("%.3f", number(r, "ssim")) << " | " << fmt("%.2f", number(r, "seconds"))
       << " | "
       << (std::isfinite(number(r, "end_to_end_seconds"))
               ? fmt("%.2f", number(r, "end_to_end_seconds"))
               : "")
       << " | " << (on_front[i] ? "yes" : "") << " |\n";
  }
  md << "\n";
  return md.str();
}

}  // namespace

bool is_run_folder(const std::string& dir) {
  return fs::is_regular_file(fs::path(dir) / "config.json");
}

namespace {

std::string margin_charts(const Section& s, FigureSet& figure_set,
                          const std::string& figures_link) {
  std::ostringstream md;
  // A bar chart of each model's margin over a baseline per light field ("margins":
  // {"over": "pinv", "target": 1.5, "stem": ...}, or an array of such charts): the
  // cross-scene benchmark. It draws the records at the chart's noise sigma ("noise", 0 by
  // default), and of each only what the chart reads (a record can hold a whole calibrated
  // Phi).
  if (s.meta.contains("margins")) {
    const auto& all = s.meta["margins"];
    const auto charts = all.is_array() ? all : nlohmann::json::array({all});
    for (std::size_t k = 0; k < charts.size(); ++k) {
      const auto& m = charts[k];
      const double sigma = m.value("noise", 0.0);
      nlohmann::json drawn = nlohmann::json::array();
      for (const auto& r : s.records) {
        if (std::abs(noise_level(r) - sigma) > 1e-9) continue;
        nlohmann::json slim;
        for (const char* key : {"light_field", "method", "variant", "psnr_db"})
          if (r.contains(key)) slim[key] = r[key];
        drawn.push_back(slim);
      }
      const std::string stem =
          m.value("stem", s.name + "_margins" + (k == 0 ? "" : "_" + std::to_string(k)));
      figure_set.add({{"kind", "margins"},
                      {"stem", stem},
                      {"title", m.value("title", s.meta.value("title", s.name))},
                      {"over", m.value("over", "pinv")},
                      {"over_variant", m.value("over_variant", "")},
                      {"series", m.value("series", nlohmann::json::array())},
                      {"target", m.contains("target") ? m["target"] : nlohmann::json()},
                      {"records", drawn}});
      const std::string over_variant = m.value("over_variant", "");
      md << figure_markdown("margins over " + m.value("over", "pinv") +
                                (over_variant.empty() ? "" : " (" + over_variant + ")") +
                                (sigma == 0 ? "" : fmt(" at noise sigma %g", sigma)),
                            figures_link, stem)
         << "\n\n";
    }
  }
  return md.str();
}

std::string training_curves(const Section& s, FigureSet& figure_set,
                            const std::string& figures_link) {
  std::ostringstream md;
  // Training curves of the models a section names ("training": [{"log": ..., "label": ...}]).
  if (s.meta.contains("training")) {
    std::string row;
    int k = 0;
    for (const auto& t : s.meta["training"]) {
      const std::string stem = s.name + "_training_" + std::to_string(k++);
      const std::string note = figure_set.training(t.at("log").get<std::string>(), stem);
      if (!note.empty()) {
        spdlog::warn("no training curves for {}: {}", t.at("log").get<std::string>(), note);
        continue;
      }
      row += "\n\n" + t.value("label", t.at("log").get<std::string>()) + ":\n\n" +
             figure_markdown("training curves", figures_link, stem);
    }
    if (!row.empty())
      md << "Training curves (loss and validation PSNR per epoch):" << row << "\n\n";
  }
  return md.str();
}

std::string sweep_figure(const Section& s, FigureSet& figure_set, const std::string& figures_link) {
  std::ostringstream md;
  if (s.meta.contains("sweep")) {
    auto spec = sweep_spec(s, s.meta["sweep"]);
    if (!spec["series"].empty()) {
      const std::string stem = spec["stem"];
      figure_set.add(std::move(spec));
      md << figure_markdown("PSNR sweep", figures_link, stem) << "\n\n";
    }
  }
  return md.str();
}

std::string view_heatmaps(const Section& s, FigureSet& figure_set,
                          const std::string& figures_link) {
  std::ostringstream md;
  // Per-view PSNR of the records named in "heatmaps" (first sensor-mode record of each): a
  // method name, or a selector of settings with an optional "label".
  if (s.meta.contains("heatmaps")) {
    auto panels = nlohmann::json::array();
    for (const auto& entry : s.meta["heatmaps"]) {
      const nlohmann::json selector = entry.is_string() ? nlohmann::json{{"method", entry}} : entry;
      std::string label = selector.value("label", selector.value("method", "?"));
      if (!selector.contains("label") && selector.contains("variant"))
        label += " (" + selector["variant"].get<std::string>() + ")";
      for (const auto& r : s.records) {
        if (!matches(r, selector) || r.value("mode", "") != "sensor" ||
            !r.contains("per_view_psnr_db"))
          continue;
        panels.push_back({{"label", label}, {"psnr", r["per_view_psnr_db"]}});
        break;
      }
    }
    if (!panels.empty()) {
      const std::string stem = s.name + "_views";
      figure_set.add({{"kind", "heatmaps"},
                      {"stem", stem},
                      {"title", s.meta.value("title", s.name) +
                                    ": PSNR per view (sensor mode; one colour range)"},
                      {"panels", panels}});
      md << "Per-view PSNR (the paper's angular-error figure):\n\n"
         << figure_markdown("per-view PSNR", figures_link, stem) << "\n\n";
    }
  }
  return md.str();
}

std::string reconstruction_pictures(const Section& s, FigureSet& figure_set,
                                    const std::string& figures_link, const std::string& drawing) {
  std::ostringstream md;
  // Pictures of reconstructions when the section names a folder that holds them.
  if (s.meta.contains("pictures")) {
    const auto& p = s.meta["pictures"];
    const fs::path dir = p.value("reconstructions", "");
    const std::string truth_dir = p.value("truth", "");
    if (fs::is_directory(dir) && fs::is_directory(truth_dir)) {
      std::vector<LightField> lfs = {io::read_light_field(truth_dir).central(5).grey()};
      std::vector<std::string> titles = {"truth"};
      for (const auto& method : p["methods"]) {
        const fs::path m = dir / method.get<std::string>();
        if (!fs::is_directory(m)) continue;
        lfs.push_back(io::read_light_field(m.string()).grey());
        titles.push_back(method.get<std::string>());
      }
      const std::string stem = s.name + "_pictures", gif = s.name + "_parallax.gif";
      figure_set.add(pictures_spec(lfs, titles, stem, figure_set));
      io::write_parallax_gif(lfs.size() > 1 ? lfs[1] : lfs[0], (fs::path(drawing) / gif).string());
      const std::string viewer = s.name + "_viewer.html";
      write_section_viewer(lfs, titles, (fs::path(drawing) / viewer).string());
      md << "Centre views, EPIs and error maps (crops):\n\n"
         << figure_markdown("reconstructions", figures_link, stem) << "\n\nParallax of the `"
         << titles[lfs.size() > 1 ? 1 : 0]
         << "` reconstruction, walking the border views: ![parallax](" << figures_link << "/" << gif
         << ")\n\n[Open it in the light-field viewer](" << figures_link << "/" << viewer
         << ") (parallax, refocus, EPIs, error map and per-view PSNR against the truth, on the "
            "central 256 x 256 pixels; docs/viewer.md). The whole light field: `"
         << (dir / titles[lfs.size() > 1 ? 1 : 0] / "index.html").generic_string() << "`.\n\n";
    } else {
      md << "*(pictures: run the section's command to make " << dir.string() << ")*\n\n";
    }
  }
  return md.str();
}

// The paper's figures beside ours, per aperture of its scene.
std::string paper_numbers(const std::vector<Claim>& claims) {
  std::ostringstream md;
  if (!claims.empty()) {
    md << "## The paper's numbers beside ours\n\n"
       << "The paper's figures against ours on its own scene, Dragons and Bunnies; the paper "
          "does not say which of the four apertures it used, so each is compared at all four. "
          "A PSNR figure counts as reproduced when ours is at most "
       << fmt("%.1f", kPsnrTolerance)
       << " dB below the paper's; a time when ours is no slower. Other scenes are compared "
          "by their margins over a baseline on the same scene, in their sections.\n\n"
       << "| section | aperture | setting | paper PSNR dB | ours | paper s | ours s | reproduced "
          "| source |\n"
       << "|---|---|---|---:|---:|---:|---:|---|---|\n";
    std::map<std::string, std::array<int, 4>> tally;  // PSNR claims, yes, time claims, yes
    for (const auto& c : claims) {
      auto& t = tally[c.scene];
      std::string verdict;
      if (!std::isnan(c.paper_psnr)) {
        const bool yes = c.ours_psnr >= c.paper_psnr - kPsnrTolerance;
        ++t[0], t[1] += yes;
        verdict +=
            yes ? "PSNR yes" : "PSNR no (" + fmt("%+.2f dB", c.ours_psnr - c.paper_psnr) + ")";
      }
      if (!std::isnan(c.paper_s)) {
        const bool yes = c.ours_s <= c.paper_s;
        ++t[2], t[3] += yes;
        verdict +=
            std::string(verdict.empty() ? "" : "; ") +
            (yes ? "time yes (" + fmt("%.0fx faster", c.paper_s / c.ours_s) + ")" : "time no");
      }
      md << "| " << c.section << " | " << c.scene << " | " << c.setting << " | "
         << (std::isnan(c.paper_psnr) ? "" : fmt("%.2f", c.paper_psnr)) << " | "
         << fmt("%.2f", c.ours_psnr) << " | " << (std::isnan(c.paper_s) ? "" : fmt("%g", c.paper_s))
         << " | " << fmt("%.2f", c.ours_s) << " | " << verdict << " | " << c.source << " |\n";
    }
    md << "\nReproduced, per aperture:\n\n";
    for (const auto& [scene, t] : tally) {
      md << "- " << scene << ": " << t[1] << " of " << t[0] << " PSNR figures, " << t[3] << " of "
         << t[2] << " times\n";
    }
    md << "\n";
  }
  return md.str();
}

// The paper's claims about differences, judged on every scene measured.
std::string paper_differences(const std::vector<GapClaim>& gaps) {
  std::ostringstream md;
  if (!gaps.empty()) {
    md << "## The paper's claims about differences\n\n"
       << "Each claim compares two of our records of the same section on the same scene (ours "
       << "= the first minus the second), so it is judged on every scene measured. Reproduced "
       << "when our difference is at least the paper's (lower) figure, less "
       << fmt("%.1f", kGapTolerance) << " dB; \"direction only\" when the paper claims "
       << "a gain and ours is a smaller gain; \"no\" otherwise (a loss, or a larger drop than "
       << "the paper's).\n\n"
       << "| section | scene | claim | paper dB | ours dB | reproduced | source "
          "|\n|---|---|---|---:|---:|---|---|\n";
    std::map<std::string, std::array<int, 3>> tally;  // claims, yes, direction only
    for (const auto& g : gaps) {
      const std::string verdict = gap_verdict(g);
      auto& t = tally[g.scene];
      ++t[0];
      t[1] += verdict == "yes";
      t[2] += verdict.rfind("direction only", 0) == 0;
      const std::string paper = g.low == g.high
                                    ? fmt("%+.1f", g.low)
                                    : fmt("%+.1f", g.low) + " to " + fmt("%+.1f", g.high);
      md << "| " << g.section << " | " << g.scene << " | " << g.claim << " | " << paper << " | "
         << (std::isnan(g.ours) ? "" : fmt("%+.2f", g.ours)) << " | " << verdict << " | "
         << g.source << " |\n";
    }
    md << "\nReproduced, per scene:\n\n";
    for (const auto& [scene, t] : tally) {
      md << "- " << scene << ": " << t[1] << " of " << t[0] << " claims; " << t[2]
         << " more in direction only\n";
    }
    md << "\n";
  }
  return md.str();
}

// A section: its text, the command that made its records, its table, margins and figures.
std::string section_markdown(const Section& s, std::vector<Claim>& claims, FigureSet& figure_set,
                             const std::string& figures_link, const std::string& drawing) {
  std::ostringstream md;
  md << "## " << s.meta.value("title", s.name) << "\n\n";
  if (s.meta.contains("text")) md << s.meta["text"].get<std::string>() << "\n\n";
  if (s.meta.contains("command"))
    md << "Records made by:\n\n    " << s.meta["command"].get<std::string>() << "\n\n";
  if (s.records.empty()) {
    md << "*No records yet.*\n\n";
    return md.str();
  }
  md << markdown_table(s, claims) << "\n";
  const auto m = margins(s);
  if (!m.empty()) md << "Margins of `net`:\n\n" << m << "\n";
  md << margin_charts(s, figure_set, figures_link) << training_curves(s, figure_set, figures_link)
     << sweep_figure(s, figure_set, figures_link) << view_heatmaps(s, figure_set, figures_link)
     << reconstruction_pictures(s, figure_set, figures_link, drawing);
  return md.str();
}

}  // namespace

void write_results_report(const std::string& results_dir, const std::string& out,
                          const std::string& figures_dir, ParetoTime time) {
  const auto sections = read_sections(results_dir);
  const fs::path out_dir =
      fs::path(out).parent_path().empty() ? fs::path(".") : fs::path(out).parent_path();
  const fs::path figures =
      figures_dir.empty() ? out_dir / "images" / "results" : fs::path(figures_dir);
  const std::string figures_link =
      fs::relative(fs::absolute(figures), fs::absolute(out_dir)).generic_string();
  OutputFolderPolicy policy;
  policy.force = true;  // the report and its figures are redrawn each time
  policy.inputs = {results_dir};
  check_output_file(out, policy);
  policy.option = "--figures";
  // The figures are drawn into a new folder that replaces the old one, and the report is written
  // last inside it: a report that fails leaves the old report and figures as they were.
  write_folder(figures.string(), policy, [&](const std::string& drawing) {
    FigureSet figure_set(drawing);
    std::ostringstream md;
    md << "# Results\n\n"
       << "Generated by `lfnet report " << results_dir << "` from the records under `"
       << results_dir
       << "/`; do not edit by hand. Each section names the command that produced its records. "
       << "PSNR and SSIM are over all views of the grey light field (docs/conventions.md, "
          "Metrics); "
          "seconds "
       << "are reconstruction wall time on the machine that ran the command. `no-parallax` (every "
       << "view set to the angular mean of the truth) is what a conventional camera records.\n\n";
    md << front_page(sections, time, figure_set, figures_link);
    std::vector<Claim> claims;
    std::vector<GapClaim> gaps;
    for (const auto& s : sections) {
      for (auto& g : gap_claims(s)) gaps.push_back(std::move(g));
      md << section_markdown(s, claims, figure_set, figures_link, drawing);
    }
    if (!claims.empty()) md << paper_numbers(claims);
    if (!gaps.empty()) md << paper_differences(gaps);
    const std::string note = figure_set.draw();
    if (!note.empty()) {
      md << "*(Figures not drawn: " << note << ")*\n";
      spdlog::warn("figures not drawn: {}", note);
    }
    fs::create_directories(out_dir);
    write_text_file(out, md.str());
  });
  spdlog::info("wrote {} ({} sections; figures in {})", out, sections.size(), figures.string());
}

}  // namespace lfnet::pipeline
