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
#include <regex>
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
#include "report_records.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

namespace {

using namespace report;

// The value of a sweep's setting in a record, as a number.
double sweep_value(const nlohmann::json& r, const std::string& key) {
  if (key == "noise") return noise_level(r);
  if (key == "n") return number(r, "measurements", 0.0);
  return number(r, key.c_str(), 0.0);
}

// The section with its light fields named by family: each name less what the regular
// expression `family` matches ("-(s|pan)[0-9]+$": a scene's moving versions are one family).
// "" leaves the names.
Section by_family(const Section& whole, const std::string& family) {
  Section s = whole;
  if (family.empty()) return s;
  std::regex pattern;
  try {
    pattern = std::regex(family);
  } catch (const std::regex_error& e) {
    throw ConfigError("section " + whole.name + ": \"family\" " + family +
                      " is no regular expression (" + e.what() + ")");
  }
  for (auto& r : s.records) {
    if (r.contains("light_field") && r["light_field"].is_string()) {
      r["light_field"] = std::regex_replace(r["light_field"].get<std::string>(), pattern, "");
    }
  }
  return s;
}

// A record's method and variant, as a table names them: "net (lfnet-video-asp-n2-t4)".
std::string method_label(const nlohmann::json& r) {
  std::string label = r.value("method", "");
  if (!r.value("variant", "").empty()) label += " (" + r.value("variant", "") + ")";
  return label;
}

// A "pivot" table of a section (docs/results.md, "A section"): each method's mean PSNR at
// each value of one setting ("x", e.g. motion_speed), over the light fields' families
// (by_family), and its mean seconds: accuracy against the setting and against time in one table.
std::string pivot_table(const Section& whole) {
  if (!whole.meta.contains("pivot")) return "";
  const auto& pivot = whole.meta["pivot"];
  const std::string key = pivot.at("x").get<std::string>();
  const Section s = by_family(whole, pivot.value("family", ""));
  std::vector<std::string> rows;  // method labels, first seen first
  std::set<double> xs;
  std::set<std::string> families;
  std::map<std::pair<std::string, double>, std::pair<double, int>> psnr;  // sum, count
  std::map<std::string, std::pair<double, int>> seconds;
  for (const auto& r : s.records) {
    const double y = number(r, "psnr_db");
    if (!std::isfinite(y)) continue;
    const auto label = method_label(r);
    if (std::find(rows.begin(), rows.end(), label) == rows.end()) rows.push_back(label);
    const double x = std::round(sweep_value(r, key) * 1000) / 1000;  // 1.9998 is 2
    xs.insert(x);
    families.insert(r.value("light_field", ""));
    auto& cell = psnr[{label, x}];
    cell.first += y;
    ++cell.second;
    const double t = number(r, "seconds");
    if (std::isfinite(t)) {
      seconds[label].first += t;
      ++seconds[label].second;
    }
  }
  if (rows.empty()) return "";
  std::ostringstream md;
  md << "Mean PSNR (dB) against " << pivot.value("label", key) << ", over";
  for (const auto& f : families) md << (f == *families.begin() ? " " : ", ") << scene_label(f);
  md << "; seconds: the mean of each method's reconstructions.\n\n| method |";
  for (const double x : xs) md << " " << fmt("%g", x) << " |";
  md << " seconds |\n|---|";
  for (size_t i = 0; i < xs.size(); ++i) md << "---:|";
  md << "---:|\n";
  for (const auto& label : rows) {
    md << "| " << label << " |";
    for (const double x : xs) {
      const auto it = psnr.find({label, x});
      md << " " << (it == psnr.end() ? "" : fmt("%.2f", it->second.first / it->second.second))
         << " |";
    }
    const auto t = seconds.find(label);
    md << " " << (t == seconds.end() ? "" : fmt("%.2f", t->second.first / t->second.second))
       << " |\n";
  }
  return md.str() + "\n";
}

// A "sweep" figure of a section: PSNR against one setting ("n", "stride" or "noise"), a series
// per method (and per other setting that varies), the paper's numbers as series of their own.
nlohmann::json sweep_spec(const Section& whole, const nlohmann::json& sweep) {
  const std::string key = sweep.at("x").get<std::string>();
  // "light_field": the sweep of one light field (or family, by_family) only (the section's
  // table keeps them all).
  const std::string only = sweep.value("light_field", "");
  const Section named = by_family(whole, sweep.value("family", ""));
  Section s = named;
  if (!only.empty()) {
    s.records.clear();
    for (const auto& r : named.records) {
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
  // Other settings that vary within one method's records name its series (e.g. "net, mode
  // per_patch"); one that only tells methods apart (a patch method's stride beside a
  // whole-image net's) does not.
  std::vector<std::string> varying;
  for (const auto& k : kSettings) {
    if (k == key || k == "method" || k == "variant") continue;
    std::map<std::string, std::set<std::string>> values;  // per method label
    for (const auto& r : s.records) values[method_label(r)].insert(setting(r, k));
    if (std::any_of(values.begin(), values.end(),
                    [](const auto& v) { return v.second.size() > 1; })) {
      varying.push_back(k);
    }
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
    std::string label = method_label(r);
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

// A method that sees no camera (no-parallax reads the true light field's centre view).
bool sees_no_camera(const nlohmann::json& r) {
  return recon::find_method(r.value("method", "")).needs() == recon::MethodNeeds::kTruth;
}

// A section whose records are the front page (`"front": true` in its section.json): measured in
// one run, so that its seconds compare.
bool is_front(const Section& s) { return s.meta.value("front", false); }

// The front page: what accuracy costs in time on the paper's scene at 5 cm (sensor mode, no
// noise), as a table and a Pareto plot per camera against `time`: the records of the front
// sections, else every method and architecture of every section once. Empty when none
// measured that scene.
std::string front_page(const std::vector<Section>& sections, ParetoTime time, FigureSet& figure_set,
                       const std::string& figures_link) {
  std::vector<const Section*> sources;
  for (const auto& s : sections) {
    if (is_front(s)) sources.push_back(&s);
  }
  const bool own_sections = !sources.empty();
  if (!own_sections) {
    for (const auto& s : sections) sources.push_back(&s);
  }
  std::vector<nlohmann::json> rows;
  std::set<std::string> seen;
  for (const Section* s : sources) {
    for (const auto& r : s->records) {
      if (r.value("light_field", "") != kFrontLightField || r.value("mode", "") != "sensor" ||
          noise_level(r) != 0 || !std::isfinite(number(r, "psnr_db")))
        continue;
      // One row per reconstruction: a model measured in two sections (or a baseline of one
      // camera) is listed once, under the first section's variant; no-parallax, which sees no
      // camera, once.
      const std::string method = r.value("method", "");
      const std::string key = sees_no_camera(r)
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
  // One plot per camera (N and Phi), fewest measurements first; no-parallax, which sees no
  // camera, is on each. A row is on the front of its own camera (no-parallax: of the first).
  using Camera = std::pair<int64_t, std::string>;  // (N, Phi name); none: (0, "")
  std::vector<Camera> row_camera;
  row_camera.reserve(rows.size());
  for (const auto& r : rows) {
    row_camera.push_back(
        sees_no_camera(r) ? Camera{} : Camera{r.value("measurements", int64_t{0}), phi_name(r)});
  }
  std::vector<Camera> cameras;
  for (const auto& c : row_camera) {
    if (c != Camera{} && std::find(cameras.begin(), cameras.end(), c) == cameras.end()) {
      cameras.push_back(c);
    }
  }
  std::sort(cameras.begin(), cameras.end());
  if (cameras.empty()) cameras.emplace_back();
  std::vector<bool> on_front(rows.size(), false);
  std::vector<std::string> plots;  // their markdown
  for (size_t c = 0; c < cameras.size(); ++c) {
    const auto& [n, phi] = cameras[c];
    std::vector<ParetoPoint> points;
    std::vector<size_t> plotted;  // the row of each point
    for (size_t i = 0; i < rows.size(); ++i) {
      if (row_camera[i] != Camera{} && row_camera[i] != cameras[c]) continue;
      if (!std::isfinite(number(rows[i], time_key))) continue;  // older records lack end to end
      auto p = pareto_point(rows[i]);
      p.seconds = number(rows[i], time_key);
      points.push_back(p);
      plotted.push_back(i);
    }
    mark_pareto_front(points);
    for (size_t k = 0; k < points.size(); ++k) {
      if (row_camera[plotted[k]] != Camera{} || c == 0) on_front[plotted[k]] = points[k].front;
    }
    // The camera's words: "ASP N = 2".
    std::string name = phi;
    for (auto& ch : name) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
    const std::string words = phi.empty() ? "" : name + " N = " + std::to_string(n);
    const std::string stem = c == 0 ? "pareto" : "pareto-" + phi + "-" + std::to_string(n);
    auto spec = pareto_spec(points,
                            "What accuracy costs in time: the paper's scene, aperture 5 cm, " +
                                words + " (sensor mode, no noise)",
                            end_to_end ? "end-to-end time of the command (s, log scale)"
                                       : "reconstruction time (s, log scale)");
    spec["stem"] = stem;
    figure_set.add(spec);
    plots.push_back(figure_markdown(words + ": PSNR against seconds", figures_link, stem));
  }
  std::vector<size_t> order(rows.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return number(rows[a], time_key, INFINITY) < number(rows[b], time_key, INFINITY);
  });
  const std::string what = end_to_end ? "end-to-end time" : "reconstruction time";
  std::ostringstream md;
  md << "## What accuracy costs in time, on the paper's scene\n\n";
  if (own_sections) {
    for (const Section* s : sources) {
      if (s->meta.contains("text")) md << s->meta["text"].get<std::string>() << "\n\n";
    }
  }
  md << (own_sections ? "On" : "Every method and architecture below on")
     << " the paper's own test scene, Dragons and Bunnies at the "
     << "5 cm aperture (593 x 840 x 5 x 5), `sensor` mode, no noise, against the " << what
     << " (`lfnet report --pareto-time`): \"seconds\" is the reconstruction alone, \"end to "
        "end\" the whole `lfnet evaluate` command as its user waits for it (loading included). "
        "One plot per camera, each with `no-parallax`, which sees none; \"on the front\" is "
        "within the row's camera. The other apertures are in the sections below (\"The paper's "
        "scene\").\n\n";
  if (own_sections) {
    md << "Records made by:\n\n";
    for (const Section* s : sources) {
      if (s->meta.contains("command"))
        md << "    " << s->meta["command"].get<std::string>() << "\n";
    }
    md << "\n";
  }
  for (const auto& plot : plots) md << plot << "\n\n";
  md << "| method | variant | N | stride | PSNR dB | SSIM | seconds | end to end s | on the front "
        "|\n|---|---|---:|---|---:|---:|---:|---:|---|\n";
  for (const size_t i : order) {
    const auto& r = rows[i];
    // A baseline's variant names the model it was measured beside, not the baseline.
    const std::string method = r.value("method", "");
    const bool camera_free = sees_no_camera(r);
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
  md << markdown_table(s, claims) << "\n" << pivot_table(s);
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
      if (is_front(s)) continue;  // it is the front page
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
