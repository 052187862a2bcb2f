#include "lfnet/pipeline/figures.h"

#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/text.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/optics/weights_image.h"
#include "lfnet/recon/method_registry.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

namespace {

// The last non-empty line of a program's output: a Python error's own line, without its
// traceback.
std::string last_line(const std::string& output) {
  size_t end = output.find_last_not_of(" \t\r\n");
  if (end == std::string::npos) return "";
  const size_t begin = output.rfind('\n', end);
  return output.substr(begin == std::string::npos ? 0 : begin + 1,
                       end - (begin == std::string::npos ? 0 : begin + 1) + 1);
}

// Runs figures.py with `args`; "" or why it failed. The script dies with lfnet (a killed report
// leaves no plotter writing behind it). A full disk is an error, not a missing figure.
std::string run_script(const std::vector<std::string>& args, const std::string& folder) {
  const std::string script = figures_script();
  if (script.empty()) return "scripts/figures.py not found (set LFNET_SCRIPTS)";
  std::vector<std::string> argv_text = {"/usr/bin/python3", script};
  argv_text.insert(argv_text.end(), args.begin(), args.end());
  std::vector<char*> argv;
  argv.reserve(argv_text.size() + 1);
  for (auto& a : argv_text) argv.push_back(a.data());
  argv.push_back(nullptr);
  int pipe_fds[2];
  if (::pipe2(pipe_fds, O_CLOEXEC) != 0)
    return std::string("cannot run python3: ") + std::strerror(errno);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(pipe_fds[0]);
    ::close(pipe_fds[1]);
    return std::string("cannot run python3: ") + std::strerror(errno);
  }
  if (pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);  // the parent died before the line above
    ::dup2(pipe_fds[1], STDOUT_FILENO);
    ::dup2(pipe_fds[1], STDERR_FILENO);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  ::close(pipe_fds[1]);
  std::string output;
  char buffer[4096];
  for (;;) {
    const ssize_t n = ::read(pipe_fds[0], buffer, sizeof(buffer));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    output.append(buffer, static_cast<size_t>(n));
  }
  ::close(pipe_fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFEXITED(status) && WEXITSTATUS(status) == 0) return "";
  if (WIFEXITED(status) && WEXITSTATUS(status) == 127 && output.empty()) {
    return "cannot run /usr/bin/python3 (install python3-matplotlib)";
  }
  LFNET_CHECK_AS(IoError, output.find("[Errno 28]") == std::string::npos,
                 "cannot draw the figures into ", folder, ": ", std::strerror(ENOSPC));
  const std::string why = last_line(output);
  if (why.find("ModuleNotFoundError") != std::string::npos) {
    return "the plot failed (install python3-matplotlib): " + why;
  }
  return "the plot failed: " + (why.empty() ? std::string("figures.py exited with an error") : why);
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

nlohmann::json pareto_spec(const std::vector<ParetoPoint>& points, const std::string& title,
                           const std::string& xlabel) {
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
  return {{"kind", "pareto"},
          {"stem", "pareto"},
          {"title", title},
          {"xlabel", xlabel},
          {"points", list}};
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
  // Stems stay relative to the folder, where the spec file is written (scripts/figures.py reads
  // them from there): the spec does not depend on where the folder is being drawn.
  specs_.push_back(std::move(spec));
}

std::string FigureSet::image(const std::string& name, const torch::Tensor& image) const {
  const fs::path relative = fs::path("data") / (name + ".png");
  const fs::path path = fs::path(folder_) / relative;
  fs::create_directories(path.parent_path());
  io::write_image(path.string(), image, 16);
  return relative.string();
}

std::string FigureSet::draw(const std::string& spec_name) const {
  if (specs_.empty()) return "";
  fs::create_directories(folder_);
  const std::string spec = (fs::path(folder_) / spec_name).string();
  // The registered methods, in order, give every figure the same colour for a method.
  write_json_file(spec, {{"figures", specs_}, {"methods", recon::registered_methods()}});
  return run_script({spec}, folder_);
}

std::string FigureSet::training(const std::string& log, const std::string& stem) const {
  fs::create_directories(folder_);
  return run_script({"training", log, (fs::path(folder_) / stem).string()}, folder_);
}

namespace {

// The figure spec of a Phi's weights: a tile per measurement and view (4 decimals: a spec of
// readable size), titled by the camera.
nlohmann::json weights_spec(const optics::Phi& phi, const std::string& stem) {
  const auto& s = phi.spec();
  const auto t = optics::weight_tiles(phi);
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
  // A calibrated Phi that says where it came from (a learned code) is named by its source.
  const bool sourced = s.name == "calibrated" && s.params.is_object() &&
                       s.params.contains("source") && s.params["source"].is_string();
  const std::string camera =
      (sourced ? s.params["source"].get<std::string>() : s.name) + ", N = " + std::to_string(s.n);
  const std::string block = std::to_string(phi.block());
  const std::string title = phi.local()
                                ? camera + ": the angular response of each measurement, M_n(u, v)"
                                : camera + ": the matrix row of each measurement over the " +
                                      block + " x " + block + " block of every view";
  return {{"kind", "weights"},
          {"stem", stem},
          {"title", title},
          {"tiles", tiles},
          {"signed", t.signed_weights},
          {"wrapped", t.wrapped},
          {"wrap", t.wrap},
          {"pixels", t.pixels},
          {"measurements", phi.measurements()},
          {"views", std::to_string(phi.rows()) + " x " + std::to_string(phi.cols())},
          {"block", phi.local() ? 0 : phi.block()}};
}

}  // namespace

std::string plot_weights(const optics::Phi& phi, const std::string& dir,
                         const OutputFolderPolicy& policy) {
  const auto& s = phi.spec();
  const std::string stem = s.name + "-n" + std::to_string(s.n);
  // Three files beside whatever DIR holds: each checked by the policy, drawn in a temporary
  // folder and moved in only when all three are complete.
  const std::vector<std::string> names = {stem + ".png", stem + ".svg", stem + ".json"};
  check_output_apart(dir, policy.inputs, policy.option);
  for (const auto& name : names) check_output_file((fs::path(dir) / name).string(), policy);
  const fs::path target = fs::path(dir) / stem;
  std::error_code ec;
  const bool made_dir = !fs::exists(dir, ec);
  // A folder made for a drawing that failed goes again (the lock file inside it goes first).
  auto lock = std::make_unique<OutputLock>(target.string(), policy.option);
  auto fail = [&] {
    lock.reset();
    if (made_dir && fs::is_empty(dir, ec)) fs::remove(dir, ec);
  };
  remove_stale_temporaries(target);
  const fs::path tmp = temporary_path(target);
  fs::remove_all(tmp, ec);
  fs::create_directories(tmp, ec);
  if (ec) fail();
  LFNET_CHECK_AS(IoError, !ec, "cannot create ", tmp.string(), ": ", ec.message());
  FigureSet figures(tmp.string());
  figures.add(weights_spec(phi, stem));
  try {
    const std::string note = figures.draw(stem + ".json");
    LFNET_CHECK_AS(IoError, note.empty(), "cannot draw the weights of ", stem, ": ", note);
    for (const auto& name : names) {
      fs::rename(tmp / name, fs::path(dir) / name, ec);
      LFNET_CHECK_AS(IoError, !ec, "cannot write ", (fs::path(dir) / name).string(), ": ",
                     ec.message());
    }
  } catch (const IoError& e) {
    fs::remove_all(tmp, ec);
    fail();
    // Named as the folder it was drawn for, not the temporary.
    throw IoError(replace_all(e.what(), tmp.string(), dir));
  } catch (...) {
    fs::remove_all(tmp, ec);
    fail();
    throw;
  }
  fs::remove_all(tmp, ec);
  return (fs::path(dir) / (stem + ".png")).string();
}

}  // namespace lfnet::pipeline
