// lfnet batch: reconstruct every acquisition folder, or evaluate every light-field folder, under
// a directory. One JSON record per item and method, a summary CSV; a bad item is recorded with
// its error and the others go on.
#include <spdlog/spdlog.h>

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "command.h"
#include "dist_flags.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/progress.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/sensor_io.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/experiment.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/pipeline/reconstruct.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/pipeline/stages.h"
#include "lfnet/recon/method_registry.h"

namespace fs = std::filesystem;

namespace lfnet::app {

namespace {

struct BatchArgs {
  std::string in, out, methods, model, dictionary, dict_method, dict_options, phi, mode = "sensor";
  int64_t stride = 5;
  int64_t batch = 1024;
  double noise = 0;
  uint64_t seed = 0;
  bool window = false, post_filter = false, match_mean = false, force = false;
  dist::DistOptions dist;  // ranks sharing the items (docs/distributed.md)
};

// One thing to process: an acquisition folder (reconstruct) or a light-field folder (evaluate).
struct BatchItem {
  std::string path;  // the folder
  std::string name;  // its path relative to --in, '/' separated
  std::string kind;  // "reconstruct", "evaluate", or "unreadable" (with `error`)
  std::string error;
};

bool looks_like_light_field(const fs::path& dir) {
  try {
    io::scan_folder(dir.string());
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

// Every acquisition and light-field folder under `root` (the root itself included), sorted; a
// folder that is an item is not searched further.
std::vector<BatchItem> discover_items(const std::string& root) {
  LFNET_CHECK_AS(IoError, fs::is_directory(root), "--input ", root, " is not a folder");
  std::vector<BatchItem> items;
  std::vector<fs::path> pending = {fs::path(root)};
  std::set<std::string> visited;  // canonical folders: a link back up is not followed again
  while (!pending.empty()) {
    const fs::path dir = pending.back();
    pending.pop_back();
    std::string name = fs::relative(dir, root).generic_string();
    if (name.empty() || name == ".")
      name = fs::absolute(dir).lexically_normal().filename().string();
    std::error_code canonical_error;
    const auto canonical = fs::canonical(dir, canonical_error);
    if (canonical_error) {
      items.push_back({dir.string(), name, "unreadable", canonical_error.message()});
      continue;
    }
    if (!visited.insert(canonical.string()).second) {
      items.push_back({dir.string(), name, "unreadable",
                       "a link to " + canonical.string() + ", which the batch already visits"});
      continue;
    }
    if (::access(dir.c_str(), R_OK | X_OK) != 0) {
      items.push_back({dir.string(), name, "unreadable", "permission denied"});
      continue;
    }
    if (fs::exists(dir / io::kSidecarName)) {
      items.push_back({dir.string(), name, "reconstruct", ""});
      continue;
    }
    if (looks_like_light_field(dir)) {
      items.push_back({dir.string(), name, "evaluate", ""});
      continue;
    }
    std::error_code ec;
    for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
      const fs::path path = it->path();
      if (path.filename().string().rfind('.', 0) == 0) continue;
      std::error_code kind_error;
      const bool is_link = fs::is_symlink(fs::symlink_status(path, kind_error));
      const auto status = fs::status(path, kind_error);
      if (is_link && kind_error) {
        const std::string rel = fs::relative(path, root).generic_string();
        items.push_back({path.string(), rel, "unreadable",
                         kind_error.value() == ELOOP
                             ? "a link that loops"
                             : "a broken link (" + kind_error.message() + ")"});
      } else if (fs::is_directory(status)) {
        pending.push_back(path);
      }
    }
    if (ec) items.push_back({dir.string(), name, "unreadable", ec.message()});
  }
  std::sort(items.begin(), items.end(),
            [](const BatchItem& a, const BatchItem& b) { return a.name < b.name; });
  return items;
}

std::vector<std::string> split_list(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream s(text);
  for (std::string part; std::getline(s, part, ',');) {
    if (!part.empty()) out.push_back(part);
  }
  return out;
}

std::string csv_field(const nlohmann::json& v) {
  std::string s = v.is_null() ? "" : v.is_string() ? v.get<std::string>() : v.dump();
  if (s.find_first_of(",\"\n") != std::string::npos) {
    std::string q = "\"";
    for (char c : s)
      q += c == '"' ? std::string("\"\"") : c == '\n' ? std::string(" ") : std::string(1, c);
    return q + "\"";
  }
  return s;
}

std::string safe_file_name(std::string name) {
  for (auto& c : name) {
    if (c == '/' || c == '\\' || c == ' ') c = '_';
  }
  return name;
}

// The records of one item, one per method; errors become records with status "error".
std::vector<nlohmann::json> process_item(const BatchItem& item, const BatchArgs& a,
                                         const std::vector<std::string>& methods,
                                         const std::string& out_dir, pipeline::ModelCache& cache) {
  std::vector<nlohmann::json> records;
  auto failed = [&](const std::string& method, const std::string& error) {
    return nlohmann::json{{"item", item.name}, {"path", item.path}, {"kind", item.kind},
                          {"method", method},  {"status", "error"}, {"error", error}};
  };
  if (item.kind == "unreadable") {
    for (const auto& method : methods) records.push_back(failed(method, item.error));
    return records;
  }
  if (item.kind == "reconstruct") {
    for (const auto& method : methods) {
      try {
        pipeline::ReconstructRequest q;
        q.sensor = item.path;
        q.method = method;
        q.model = a.model;
        q.dictionary = a.dictionary;
        q.dict_method = a.dict_method;
        q.dict_options = a.dict_options;
        q.options.stride = a.stride;
        q.options.batch = a.batch;
        q.options.window = a.window;
        q.post_filter = a.post_filter;
        q.match_mean = a.match_mean;
        auto r = pipeline::reconstruct_acquisition(q, {}, &cache);
        const std::string target = (fs::path(out_dir) / item.name / method).string();
        OutputFolderPolicy policy;
        policy.inputs = {item.path, a.model, a.dictionary};
        pipeline::write_reconstruction(r, target, policy);
        auto record = r.record;
        record["item"] = item.name;
        record["path"] = item.path;
        record["kind"] = item.kind;
        record["status"] = "ok";
        record["output"] = target;
        records.push_back(record);
      } catch (const std::exception& e) {
        records.push_back(failed(method, e.what()));
      }
    }
    return records;
  }
  // evaluate: simulate with the model's Phi (or --phi), reconstruct, score.
  std::vector<pipeline::NamedLightField> truths;
  pipeline::MethodContext context;
  std::unique_ptr<optics::Phi> phi;
  std::optional<nn::PatchShape> patch;  // the model's, when there is one
  try {
    optics::PhiSpec spec;
    if (!a.model.empty()) {
      const auto& model = cache.model(a.model);
      spec = optics::PhiSpec::from_json(model.phi, a.model + ":$.phi");
      context.net = model.net;
      context.script = model.script;
      patch = model.network.patch;
    } else {
      LFNET_CHECK_AS(ConfigError, !a.phi.empty(),
                     "evaluating light-field folders needs --model or --phi");
      spec = pipeline::phi_from_argument(a.phi);
    }
    phi = optics::make_phi(spec);
    context.phi = phi.get();
    context.dictionary = a.dictionary;
    context.cache = &cache;
    context.dict_method = a.dict_method;
    context.dict_options = a.dict_options;
    pipeline::LightFieldSources sources;
    sources.light_fields = {item.path};
    truths = pipeline::load_sources(sources, phi->rows(), phi->cols());
  } catch (const std::exception& e) {
    for (const auto& method : methods) records.push_back(failed(method, e.what()));
    return records;
  }
  for (const auto& method : methods) {
    try {
      const auto o =
          pipeline::make_eval_options(a.mode, a.noise, a.seed, a.stride, a.batch, a.window, patch);
      auto record = pipeline::evaluate_method(truths[0], method, context, o, nullptr, false);
      record["item"] = item.name;
      record["path"] = item.path;
      record["kind"] = item.kind;
      record["status"] = "ok";
      const auto needs = recon::find_method(method).needs();
      if (needs == recon::MethodNeeds::kNetwork) record["model"] = a.model;
      if (needs == recon::MethodNeeds::kDictionary) record["model"] = a.dictionary;
      records.push_back(record);
    } catch (const std::exception& e) {
      records.push_back(failed(method, e.what()));
    }
  }
  return records;
}

void write_summary(const std::string& out_dir, const std::vector<nlohmann::json>& records) {
  const std::vector<std::string> columns = {"item",    "kind",   "method",  "status",
                                            "psnr_db", "ssim",   "seconds", "stride",
                                            "mode",    "output", "error"};
  const fs::path csv = fs::path(out_dir) / "summary.csv";
  std::ostringstream f;
  {
    for (size_t i = 0; i < columns.size(); ++i) f << (i ? "," : "") << columns[i];
    f << "\n";
    for (const auto& r : records) {
      for (size_t i = 0; i < columns.size(); ++i) {
        f << (i ? "," : "") << (r.contains(columns[i]) ? csv_field(r[columns[i]]) : "");
      }
      f << "\n";
    }
  }
  write_text_file(csv.string(), f.str());
  nlohmann::json all = nlohmann::json::array();
  for (const auto& r : records) all.push_back(r);
  write_json_file((fs::path(out_dir) / "summary.json").string(), all);
}

void run_batch(const BatchArgs& a) {
  auto comm = join_job(a.dist);
  const int64_t rank = comm->rank(), world = comm->world_size();
  OutputFolderPolicy policy;
  policy.force = a.force;
  policy.inputs = {a.in, a.model, a.dictionary};
  check_output_folder(a.out, policy);
  const auto items = discover_items(a.in);
  LFNET_CHECK_AS(ConfigError, !items.empty(), "no acquisition folder (with ", io::kSidecarName,
                 ") and no light-field folder under ", a.in);
  std::vector<std::string> methods = split_list(a.methods);
  if (methods.empty()) methods = {a.model.empty() ? "pinv" : "net"};
  for (const auto& m : methods) {
    try {
      (void)recon::find_method(m);
    } catch (const ConfigError& e) {
      throw ConfigError(std::string("--methods: ") + e.what());
    }
  }
  LFNET_CHECK_AS(ConfigError, a.noise >= 0, "--noise must be >= 0");
  LFNET_CHECK_AS(ConfigError,
                 std::find(methods.begin(), methods.end(), "dict") != methods.end() ||
                     (a.dict_method.empty() && a.dict_options.empty()),
                 "--dict-method and --dict-options apply to the dict method, which --methods does "
                 "not name");
  std::unique_ptr<RunFolder> folder;  // rank 0 makes it; the others write into it
  if (rank == 0) folder = std::make_unique<RunFolder>(a.out, policy);
  // The other ranks write only once rank 0 has checked and made the folder (when it is shared).
  comm->barrier();
  const fs::path records_dir = fs::path(a.out) / "records";
  fs::create_directories(records_dir);
  int64_t reconstruct = 0;
  for (const auto& it : items) reconstruct += it.kind == "reconstruct";
  spdlog::info("batch: {} item(s) under {} ({} to reconstruct, {} to evaluate), methods {}",
               items.size(), a.in, reconstruct, items.size() - reconstruct,
               a.methods.empty() ? methods[0] : a.methods);

  // Rank r takes items r, r + W, r + 2W, ... of the sorted list: neighbours in the list (often
  // alike in size) go to different ranks.
  std::vector<size_t> mine;
  for (size_t i = static_cast<size_t>(rank); i < items.size(); i += static_cast<size_t>(world)) {
    mine.push_back(i);
  }
  if (world > 1) {
    spdlog::info("batch: {} rank(s), rank 0 takes {} item(s)", world, mine.size());
  }
  std::vector<nlohmann::json> records;
  std::vector<size_t> record_item;  // the item index of every record, for the gather
  ProgressBar bar("batch", static_cast<int64_t>(mine.size()), "items");
  int64_t failures = 0;
  pipeline::ModelCache cache;  // every item shares one read of the model and the dictionary
  for (size_t index : mine) {
    const auto& item = items[index];
    bar.set_note(item.name);
    for (auto& r : process_item(item, a, methods, a.out, cache)) {
      const bool ok = r["status"] == "ok";
      failures += !ok;
      const std::string file =
          safe_file_name(item.name) + "__" + r["method"].get<std::string>() + ".json";
      write_json_file((records_dir / file).string(), r);
      if (folder) folder->commit();  // a record lasts: the batch keeps its folder from now on
      if (ok && r.contains("psnr_db")) {
        spdlog::info("{} {}: PSNR {:.2f} dB, SSIM {:.4f}, {:.2f} s", item.name,
                     r["method"].get<std::string>(),
                     r["psnr_db"].is_null() ? INFINITY : r["psnr_db"].get<double>(),
                     r["ssim"].get<double>(), r["seconds"].get<double>());
      } else if (ok) {
        spdlog::info("{} {}: {:.2f} s -> {}", item.name, r["method"].get<std::string>(),
                     r["seconds"].get<double>(), r["output"].get<std::string>());
      } else {
        spdlog::warn("{} {}: {}", item.name, r["method"].get<std::string>(),
                     r["error"].get<std::string>());
      }
      records.push_back(std::move(r));
      record_item.push_back(index);
    }
    bar.advance(1);
  }
  bar.finish();
  if (world > 1) {
    // One summary on rank 0: every rank's records, back in the order of one process.
    nlohmann::json shipped = nlohmann::json::array();
    for (size_t i = 0; i < records.size(); ++i) shipped.push_back({record_item[i], records[i]});
    const auto gathered = comm->all_gather(shipped.dump());
    if (rank != 0) return;  // rank 0 writes the summary and reports failures
    std::vector<std::pair<size_t, nlohmann::json>> all;
    for (const auto& part : gathered) {
      for (auto& entry : nlohmann::json::parse(part)) {
        all.emplace_back(entry[0].get<size_t>(), std::move(entry[1]));
      }
    }
    std::stable_sort(all.begin(), all.end(),
                     [](const auto& x, const auto& y) { return x.first < y.first; });
    records.clear();
    failures = 0;
    for (auto& entry : all) {
      failures += entry.second["status"] != "ok";
      records.push_back(std::move(entry.second));
    }
  }
  write_summary(a.out, records);
  if (folder) folder->commit();
  spdlog::info(
      "batch: {} record(s), {} failed; summary in {}/summary.csv; {} model or dictionary file(s) "
      "read",
      records.size(), failures, a.out, cache.loads());
  LFNET_CHECK(failures == 0, failures, " of ", records.size(), " item-method pair(s) failed; see ",
              a.out, "/summary.csv (the others are done)");
}

}  // namespace

void add_batch_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "batch",
      "Reconstruct every acquisition folder, or evaluate every light-field folder, under a "
      "directory");
  auto a = std::make_shared<BatchArgs>();
  cmd->add_option("--input,--in", a->in, "folder to search (recursively) for items")->required();
  cmd->add_option("--out", a->out,
                  "output folder: reconstructions, records/, summary.csv, summary.json")
      ->required();
  cmd->add_option("--methods", a->methods,
                  "comma-separated methods (default net with --model, pinv without)");
  cmd->add_option("--model", a->model,
                  "trained model for net, ae and cnn: a checkpoint or a file lfnet export wrote");
  cmd->add_option("--dictionary", a->dictionary, "dictionary file for dict");
  add_dict_coding_options(cmd, a->dict_method, a->dict_options);
  cmd->add_option(
      "--phi", a->phi,
      "Phi for evaluation without --model: NAME[:N], a spec or a calibrated-Phi folder");
  cmd->add_option("--mode", a->mode, "simulation mode of evaluations: sensor or per_patch")
      ->check(CLI::IsMember({"sensor", "per_patch"}));
  cmd->add_option("--noise", a->noise, "Gaussian noise sigma of evaluations")
      ->check(kFiniteNonNegative);
  cmd->add_option("--seed", a->seed, "noise seed of evaluations");
  cmd->add_option("--stride", a->stride, "patch stride (default 5)")->check(kStride);
  cmd->add_option("--batch", a->batch, "patches per solver call")->check(CLI::PositiveNumber);
  cmd->add_flag("--window", a->window, "weight patch estimates by a smooth window when stitching");
  cmd->add_flag("--post-filter", a->post_filter, "suppress artefacts with the stride's period");
  cmd->add_flag("--match-mean", a->match_mean, "scale real measurements to the training mean");
  cmd->add_flag("--force", a->force, "write into an existing non-empty output folder");
  add_dist_flags(cmd, a->dist);
  cmd->callback([a] { run_batch(*a); });
}

}  // namespace lfnet::app
