// The tables of lfnet report: a section's records, the margins of net, and the paper's figures
// and claims beside ours (report_records.h).
#include <cmath>
#include <functional>
#include <map>
#include <set>
#include <sstream>
#include <utility>

#include "lfnet/pipeline/sets.h"
#include "report_records.h"

namespace lfnet::pipeline::report {

namespace {

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
    if (any("per_frame_psnr_db")) {  // sequences (docs/video.md): each sub-frame's PSNR
      results_.push_back({"per frame dB", [](const nlohmann::json& r) {
                            std::string text;
                            if (!r.contains("per_frame_psnr_db")) return text;
                            for (const auto& p : r["per_frame_psnr_db"]) {
                              text += (text.empty() ? "" : " / ") +
                                      (p.is_number() ? fmt("%.2f", p.get<double>()) : "inf");
                            }
                            return text;
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

}  // namespace

std::string markdown_table(const Section& s, std::vector<Claim>& claims) {
  return RecordTable(s, claims).markdown();
}

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

}  // namespace lfnet::pipeline::report
