#include "lfnet/pipeline/figures.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/optics/weights_image.h"
#include "lfnet/recon/method_registry.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

namespace {

std::string quote(const std::string& s) {
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

// Runs figures.py with `args`; "" or why it failed.
std::string run_script(const std::string& args) {
  const std::string script = figures_script();
  if (script.empty()) return "scripts/figures.py not found (set LFNET_SCRIPTS)";
  const std::string command = "/usr/bin/python3 " + quote(script) + " " + args + " 2>&1";
  FILE* pipe = ::popen(command.c_str(), "r");
  if (!pipe) return "cannot run /usr/bin/python3";
  std::string output;
  char buffer[256];
  while (std::fgets(buffer, sizeof(buffer), pipe)) output += buffer;
  const int status = ::pclose(pipe);
  if (status != 0) return "the plot failed (python3-matplotlib installed?): " + output;
  return "";
}

}  // namespace

ParetoPoint pareto_point(const nlohmann::json& record) {
  ParetoPoint p;
  p.method = record.value("method", "");
  p.variant = record.value("variant", "");
  p.n = record.value("measurements", int64_t{0});
  p.stride = record.value("stride", int64_t{0});
  p.whole_image = record.value("whole_image", false);
  p.seconds = record.value("seconds", 0.0);
  p.psnr_db = record.at("psnr_db").get<double>();
  return p;
}

void mark_pareto_front(std::vector<ParetoPoint>& points) {
  std::vector<size_t> order(points.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return points[a].seconds != points[b].seconds ? points[a].seconds < points[b].seconds
                                                  : points[a].psnr_db > points[b].psnr_db;
  });
  double best = -INFINITY;
  for (size_t i : order) {
    points[i].front = points[i].psnr_db > best;
    best = std::max(best, points[i].psnr_db);
  }
}

nlohmann::json pareto_spec(const std::vector<ParetoPoint>& points, const std::string& title) {
  auto list = nlohmann::json::array();
  for (const auto& p : points) {
    list.push_back({{"method", p.method},
                    {"variant", p.variant},
                    {"n", p.n},
                    {"stride", p.stride},
                    {"whole_image", p.whole_image},
                    {"seconds", p.seconds},
                    {"psnr_db", p.psnr_db},
                    {"front", p.front}});
  }
  return {{"kind", "pareto"}, {"stem", "pareto"}, {"title", title}, {"points", list}};
}

std::string figures_script() {
  std::vector<std::string> candidates;
  if (const char* env = std::getenv("LFNET_SCRIPTS")) candidates.emplace_back(env);
#ifdef LFNET_SCRIPTS_DIR
  candidates.emplace_back(LFNET_SCRIPTS_DIR);
#endif
  candidates.emplace_back("scripts");
  for (const auto& dir : candidates) {
    const fs::path p = fs::path(dir) / "figures.py";
    if (fs::exists(p)) return p.string();
  }
  return "";
}

std::vector<nlohmann::json> read_jsonl(const std::string& path) {
  std::ifstream in(path);
  LFNET_CHECK_AS(IoError, in, "cannot read ", path);
  std::vector<nlohmann::json> out;
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    try {
      out.push_back(nlohmann::json::parse(line));
    } catch (const nlohmann::json::exception&) {
      throw IoError(path + ":" + std::to_string(n) + ": not a JSON record");
    }
  }
  return out;
}

FigureSet::FigureSet(std::string folder) : folder_(std::move(folder)) {}

void FigureSet::add(nlohmann::json spec) {
  spec["stem"] = (fs::path(folder_) / spec.at("stem").get<std::string>()).string();
  specs_.push_back(std::move(spec));
}

std::string FigureSet::image(const std::string& name, const torch::Tensor& image) const {
  const fs::path path = fs::path(folder_) / "data" / (name + ".png");
  fs::create_directories(path.parent_path());
  io::write_image(path.string(), image, 16);
  return path.string();
}

std::string FigureSet::draw(const std::string& spec_name) const {
  if (specs_.empty()) return "";
  fs::create_directories(folder_);
  const std::string spec = (fs::path(folder_) / spec_name).string();
  // The registered methods, in order, give every figure the same colour for a method.
  write_json_file(spec, {{"figures", specs_}, {"methods", recon::registered_methods()}});
  return run_script(quote(spec));
}

std::string FigureSet::training(const std::string& log, const std::string& stem) const {
  fs::create_directories(folder_);
  return run_script("training " + quote(log) + " " + quote((fs::path(folder_) / stem).string()));
}

std::string plot_weights(const optics::Phi& phi, const std::string& dir) {
  const auto& s = phi.spec();
  const std::string stem = s.name + "-n" + std::to_string(s.n);
  const auto t = optics::weight_tiles(phi);
  // 4 decimals: a spec of readable size.
  const auto rounded = ((t.tiles * 1e4).round() / 1e4).contiguous();
  const auto a = rounded.accessor<double, 4>();
  nlohmann::json tiles = nlohmann::json::array();
  for (int64_t i = 0; i < a.size(0); ++i) {
    auto row = nlohmann::json::array();
    for (int64_t j = 0; j < a.size(1); ++j) {
      std::vector<std::vector<double>> tile(a.size(2));
      for (int64_t y = 0; y < a.size(2); ++y) {
        for (int64_t x = 0; x < a.size(3); ++x) tile[y].push_back(a[i][j][y][x]);
      }
      row.push_back(tile);
    }
    tiles.push_back(row);
  }
  const std::string camera = s.name + ", N = " + std::to_string(s.n);
  const std::string block = std::to_string(phi.block());
  const std::string title = phi.local()
                                ? camera + ": the angular response of each measurement, M_n(u, v)"
                                : camera + ": the matrix row of each measurement over the " +
                                      block + " x " + block + " block of every view";
  FigureSet figures(dir);
  figures.add({{"kind", "weights"},
               {"stem", stem},
               {"title", title},
               {"tiles", tiles},
               {"signed", t.signed_weights},
               {"wrapped", t.wrapped},
               {"wrap", t.wrap},
               {"measurements", phi.measurements()},
               {"views", std::to_string(phi.rows()) + " x " + std::to_string(phi.cols())},
               {"block", phi.local() ? 0 : phi.block()}});
  const std::string note = figures.draw(stem + ".json");
  LFNET_CHECK_AS(IoError, note.empty(), "cannot draw the weights of ", stem, ": ", note);
  return (fs::path(dir) / (stem + ".png")).string();
}

}  // namespace lfnet::pipeline
