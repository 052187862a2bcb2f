#include "lfnet/pipeline/batch.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <filesystem>
#include <optional>
#include <set>
#include <sstream>
#include <utility>

#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/text.h"
#include "lfnet/io/light_field_io.h"
#include "lfnet/io/sensor_io.h"
#include "lfnet/nn/auto_precision.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/pipeline/evaluate.h"
#include "lfnet/pipeline/reconstruct.h"
#include "lfnet/pipeline/sources.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/method_registry.h"

namespace fs = std::filesystem;

namespace lfnet::pipeline {

namespace {

// Every file a batch reads besides its items: the model (a noise switch's members too), the
// dictionary, the flat field and the files of its JSON options; never overwritten.
std::vector<std::string> batch_inputs(const BatchOptions& a) {
  auto inputs = model_input_files(a.model);
  inputs.insert(inputs.end(), {a.dictionary, a.flat_field, json_argument_file(a.method_options),
                               json_argument_file(a.cfa)});
  return inputs;
}

// "" for a light-field folder, why it cannot be read for a folder that holds view files but no
// complete light field (a missing view, a view that is a folder, two naming schemes), nullopt
// for a folder of anything else.
std::optional<std::string> light_field_problem(const fs::path& dir) {
  try {
    io::scan_folder(dir.string());
    return "";
  } catch (const std::exception& e) {
    if (!io::holds_view_names(dir.string())) return std::nullopt;
    return std::string(e.what());
  }
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

}  // namespace

std::vector<BatchItem> discover_items(const std::string& root) {
  std::error_code root_error;
  const bool root_is_folder = fs::is_directory(root, root_error);
  LFNET_CHECK_AS(IoError, root_is_folder, "--input ", root,
                 root_error.value() == ELOOP ? " is a link that loops"
                 : root_error && root_error != std::errc::no_such_file_or_directory
                     ? ": " + root_error.message()
                 : fs::exists(fs::symlink_status(root, root_error)) ? " is not a folder"
                                                                    : " does not exist");
  std::vector<BatchItem> items;
  std::vector<fs::path> pending = {fs::path(root)};
  std::set<std::string> visited;  // canonical folders: a link back up is not followed again
  while (!pending.empty()) {
    const fs::path dir = pending.back();
    pending.pop_back();
    std::string name = dir.lexically_relative(root).generic_string();
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
    if (const auto problem = light_field_problem(dir)) {
      // A light field that cannot be read is a failed item, not a folder to skip.
      items.push_back(problem->empty() ? BatchItem{dir.string(), name, "evaluate", ""}
                                       : BatchItem{dir.string(), name, "unreadable", *problem});
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
        const std::string rel = path.lexically_relative(root).generic_string();
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

std::vector<nlohmann::json> process_item(const BatchItem& item, const BatchOptions& a,
                                         const std::vector<std::string>& methods,
                                         const std::string& out_dir, ModelCache& cache) {
  std::vector<nlohmann::json> records;
  auto failed = [&](const std::string& method, const std::string& error) {
    return nlohmann::json{{"item", item.name}, {"path", item.path},
                          {"kind", item.kind}, {"method", method},
                          {"status", "error"}, {"error", without_source_locations(error)}};
  };
  if (item.kind == "unreadable") {
    for (const auto& method : methods) records.push_back(failed(method, item.error));
    return records;
  }
  if (item.kind == "reconstruct") {
    // What holds for every method, checked once per item: --phi against the model, and the
    // methods' options (checked for all methods at the start, read again here).
    nlohmann::json all_options;
    try {
      if (!a.model.empty()) check_phi_argument(cache.model(a.model), a.phi);
      all_options = method_options_argument(a.method_options, methods);
    } catch (const std::exception& e) {
      for (const auto& method : methods) records.push_back(failed(method, e.what()));
      return records;
    }
    for (const auto& method : methods) {
      try {
        ReconstructRequest q;
        q.sensor = item.path;
        q.method = method;
        q.model = a.model;
        q.dictionary = a.dictionary;
        if (all_options.contains(method)) {
          q.method_options = nlohmann::json{{method, all_options[method]}}.dump();
        }
        q.options.stride = a.stride;
        q.options.batch = a.batch;
        q.options.window = a.window;
        q.post_filter = a.post_filter;
        q.match_mean = a.match_mean;
        q.flat_field = a.flat_field;
        q.demosaic = a.demosaic;
        q.self_ensemble = a.self_ensemble;
        q.self_ensemble_passes = a.self_ensemble_passes;
        q.self_calibrate = a.self_calibrate;
        q.device = a.device;
        q.precision = a.precision;
        q.tile = a.tile;
        q.coded = true;  // as reconstruct: a grey light field in 16-bit codes
        auto r = reconstruct_acquisition(q, {}, &cache);
        const std::string target = (fs::path(out_dir) / item.name / method).string();
        OutputFolderPolicy policy;
        policy.inputs = batch_inputs(a);
        policy.inputs.push_back(item.path);
        policy.force = a.resume;  // an output without its record is an unfinished attempt
        write_reconstruction(r, target, policy,
                             /*end_to_end=*/false);  // the batch's, not the item's
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
  std::vector<NamedLightField> truths;
  MethodContext context;
  std::unique_ptr<optics::Phi> phi;
  std::optional<nn::PatchShape> patch;           // the model's, when there is one
  std::optional<optics::ColourFilterArray> cfa;  // --cfa, inline once the batch has read it
  try {
    optics::PhiSpec spec;
    if (!a.model.empty()) {
      const auto& model = cache.model(a.model);
      spec = optics::PhiSpec::from_json(model.phi, a.model + ":$.phi");
      check_phi_argument(model, a.phi);
      place_network(model, a.device, a.precision);
      use_model(context, model);
      patch = model.network.patch_grid();
    } else {
      LFNET_CHECK_AS(ConfigError, !a.phi.empty(),
                     "evaluating light-field folders needs --model or --phi");
      spec = phi_from_argument(a.phi);
    }
    phi = optics::make_phi(spec);
    context.phi = phi.get();
    context.dictionary = a.dictionary;
    context.cache = &cache;
    context.method_options = method_options_argument(a.method_options, methods);
    context.self_ensemble = a.self_ensemble;
    context.self_ensemble_passes = a.self_ensemble_passes;
    context.self_calibrate = a.self_calibrate;
    context.tile = a.tile;
    LightFieldSources sources;
    sources.light_fields = {item.path};
    // As evaluate: a grey truth of 16-bit views in 16-bit codes.
    truths = load_sources(sources, phi->rows(), phi->cols(), false, !a.cfa.empty(), a.cfa.empty());
    if (!a.cfa.empty()) cfa = optics::ColourFilterArray::parse(a.cfa);
  } catch (const std::exception& e) {
    for (const auto& method : methods) records.push_back(failed(method, e.what()));
    return records;
  }
  for (const auto& method : methods) {
    try {
      if (!a.model.empty() && recon::needs_network(method)) {
        cache.model(a.model).check_cfa(cfa ? cfa->pattern() : "");
      }
      auto o = make_eval_options(a.mode, a.noise, a.seed, a.stride, a.batch, a.window, patch);
      o.cfa = cfa;
      // A colour net demosaics inside itself: --demosaic is for the other methods.
      check_demosaic_argument(a.demosaic, cfa.has_value(), false, method);
      o.demosaic = a.demosaic;
      context.coded = o.reconstruct.coded = !cfa;  // as evaluate: a grey estimate in 16-bit codes
      auto record = evaluate_method(truths[0], method, context, o, nullptr, false);
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

void write_batch_summary(const std::string& out_dir, const std::vector<nlohmann::json>& records) {
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

nlohmann::json batch_manifest(const BatchOptions& a, const std::vector<std::string>& methods) {
  auto absolute = [](const std::string& p) {
    return p.empty() ? p : fs::absolute(p).lexically_normal().string();
  };
  nlohmann::json options = {{"input", absolute(a.in)},
                            {"methods", methods},
                            {"model", absolute(a.model)},
                            {"dictionary", absolute(a.dictionary)},
                            {"phi", a.phi},
                            {"method_options", a.method_options},
                            {"mode", optics::to_string(a.mode)},
                            {"noise", a.noise},
                            {"cfa", a.cfa},
                            {"demosaic", optics::to_string(a.demosaic)},
                            {"seed", a.seed},
                            {"stride", a.stride},
                            {"window", a.window},
                            {"post_filter", a.post_filter},
                            {"match_mean", a.match_mean},
                            {"self_ensemble", a.self_ensemble},
                            {"self_ensemble_passes", a.self_ensemble_passes}};
  // Only when given, so that batches from before the option resume as they were.
  if (!a.flat_field.empty()) options["flat_field"] = absolute(a.flat_field);
  // What the files hold, not only where they are: a model replaced under the same path would
  // mix two networks in one summary (a noise switch: its members' contents too).
  for (const auto& [key, path] : {std::pair<std::string, std::string>{"model_content", a.model},
                                  {"dictionary_content", a.dictionary}}) {
    if (path.empty() || !fs::is_regular_file(path)) continue;
    std::string content;
    for (const auto& file : model_input_files(path)) {
      if (fs::is_regular_file(file))
        content += (content.empty() ? "" : ",") + nn::file_fingerprint(file);
    }
    options[key] = content;
  }
  if (a.self_calibrate) options["self_calibrate"] = true;
  return options;
}

namespace {

std::string record_file(const std::string& item, const std::string& method) {
  return safe_file_name(item) + "__" + method + ".json";
}

// `--resume`: OUT holds a batch of the same options (its batch.json).
void check_resumable(const BatchOptions& a, const nlohmann::json& manifest) {
  const fs::path out(a.out);
  LFNET_CHECK_AS(ConfigError, !a.force, "--resume continues the batch in ", a.out,
                 " and --force would replace it: give one of them");
  const fs::path file = out / "batch.json";
  std::error_code ec;
  LFNET_CHECK_AS(ConfigError, fs::is_regular_file(file, ec), "--resume: ", a.out,
                 " holds no batch to continue (no batch.json); run without --resume to start one");
  const auto earlier = read_json_file(file.string());
  for (const auto& [key, value] : manifest.items()) {
    // Batches whose batch.json predates the content fingerprints are checked by path alone.
    if (key == "model_content" || key == "dictionary_content") {
      if (!earlier.contains(key)) continue;
      const auto& path = key == "model_content" ? a.model : a.dictionary;
      LFNET_CHECK_AS(ConfigError, earlier[key] == value, "--resume: ", path,
                     " is not the file the batch in ", a.out,
                     " began with (its content differs): give that file, or another --out");
      continue;
    }
    LFNET_CHECK_AS(ConfigError, earlier.contains(key) && earlier[key] == value,
                   "--resume: the batch in ", a.out, " was run with ", key, " = ",
                   earlier.contains(key) ? earlier[key].dump() : std::string("nothing"),
                   ", this command gives ", value.dump(),
                   "; give the same options, or another --out");
  }
}

// The record of a pair done earlier, when it is there and says "ok".
std::optional<nlohmann::json> finished_record(const fs::path& file) {
  std::error_code ec;
  if (!fs::is_regular_file(file, ec)) return std::nullopt;
  try {
    auto record = read_json_file(file.string());
    if (record.value("status", "") == "ok") return record;
  } catch (const std::exception&) {
    // Unreadable: done again.
  }
  return std::nullopt;
}

}  // namespace

BatchSummary run_batch(const BatchOptions& a, std::shared_ptr<dist::Communicator> comm) {
  if (!comm) comm = std::make_shared<dist::LocalCommunicator>();
  const int64_t rank = comm->rank(), world = comm->world_size();
  std::vector<std::string> methods = a.methods;
  if (methods.empty()) methods = {a.model.empty() ? "pinv" : "net"};
  for (const auto& m : methods) {
    try {
      (void)recon::find_method(m);
    } catch (const ConfigError& e) {
      throw ConfigError(std::string("--methods: ") + e.what());
    }
  }
  // Checked before any work, and read once: the items take them inline, not from a file again.
  BatchOptions resolved = a;
  const auto method_options = method_options_argument(a.method_options, methods);
  resolved.method_options = method_options.empty() ? "" : method_options.dump();
  // --cfa, or the one a calibrated Phi's folder names.
  if (const auto cfa = cfa_of_arguments(a.cfa, a.phi)) {
    cfa->check_demosaicable();
    resolved.cfa = cfa->to_json().dump();
  }
  const auto manifest = batch_manifest(a, methods);
  OutputFolderPolicy policy;
  policy.force = a.force;
  policy.inputs = batch_inputs(a);
  policy.inputs.push_back(a.in);
  if (a.resume) {
    check_resumable(a, manifest);
  } else {
    try {
      check_output_folder(a.out, policy);
    } catch (const ConfigError& e) {
      std::error_code ec;
      if (!fs::is_regular_file(fs::path(a.out) / "batch.json", ec)) throw;
      throw ConfigError(std::string(e.what()) + "; it holds a batch: --resume continues it");
    }
  }
  const auto items = discover_items(a.in);
  LFNET_CHECK_AS(ConfigError, !items.empty(), "no acquisition folder (with ", io::kSidecarName,
                 ") and no light-field folder under ", a.in);
  LFNET_CHECK_AS(ConfigError, a.noise >= 0, "--noise must be >= 0");
  ModelCache cache;  // every item shares one read of the model and the dictionary
  recon::check_ensemble_passes(a.self_ensemble, a.self_ensemble_passes);
  if (a.self_ensemble) {
    LFNET_CHECK_AS(ConfigError, !a.model.empty(),
                   "--self-ensemble applies to --method net with a model of the lfnet "
                   "architecture: pass --model");
    const auto& model = cache.model(a.model);
    for (const auto& m : methods) recon::check_self_ensemble(m, model.net, model.script.get());
  }
  std::unique_ptr<RunFolder> folder;  // rank 0 makes it; the others write into it
  if (rank == 0) folder = std::make_unique<RunFolder>(a.out, policy, a.resume);
  // The other ranks write only once rank 0 has checked and made the folder (when it is shared),
  // and rank 0 writes into it only once they have checked it.
  comm->barrier();
  if (rank == 0 && !a.resume) {
    write_json_file((fs::path(a.out) / "batch.json").string(), manifest);
  }
  const fs::path records_dir = fs::path(a.out) / "records";
  fs::create_directories(records_dir);
  int64_t reconstruct = 0;
  for (const auto& it : items) reconstruct += it.kind == "reconstruct";
  std::string method_list;
  for (const auto& m : methods) method_list += (method_list.empty() ? "" : ",") + m;
  spdlog::info("batch: {} item(s) under {} ({} to reconstruct, {} to evaluate), methods {}",
               items.size(), a.in, reconstruct, items.size() - reconstruct, method_list);

  // The pairs still to do (all of them unless resumed), and the records of those done.
  struct Pending {
    size_t item;
    std::vector<std::string> methods;
  };
  std::vector<Pending> pending;
  std::vector<std::pair<std::pair<size_t, size_t>, nlohmann::json>>
      kept;  // ((item, method), record)
  for (size_t i = 0; i < items.size(); ++i) {
    Pending p{i, {}};
    for (size_t m = 0; m < methods.size(); ++m) {
      auto done = a.resume ? finished_record(records_dir / record_file(items[i].name, methods[m]))
                           : std::nullopt;
      if (done) {
        kept.emplace_back(std::make_pair(i, m), std::move(*done));
      } else {
        p.methods.push_back(methods[m]);
      }
    }
    if (!p.methods.empty()) pending.push_back(std::move(p));
  }
  if (a.resume) {
    spdlog::info("batch: resumed; {} of {} item-method pair(s) done before, {} item(s) to do",
                 kept.size(), items.size() * methods.size(), pending.size());
  }

  // Rank r takes pending items r, r + W, r + 2W, ...: neighbours in the list (often alike in
  // size) go to different ranks.
  std::vector<size_t> mine;
  for (size_t i = static_cast<size_t>(rank); i < pending.size(); i += static_cast<size_t>(world)) {
    mine.push_back(i);
  }
  if (world > 1) {
    spdlog::info("batch: {} rank(s), rank 0 takes {} item(s)", world, mine.size());
  }
  auto method_index = [&](const nlohmann::json& r) {
    const auto name = r["method"].get<std::string>();
    return static_cast<size_t>(std::find(methods.begin(), methods.end(), name) - methods.begin());
  };
  BatchSummary summary;
  std::vector<std::pair<size_t, size_t>> record_key;  // (item, method) of every record
  ProgressBar bar("batch", static_cast<int64_t>(mine.size()), "items");
  for (size_t p : mine) {
    const size_t index = pending[p].item;
    const auto& item = items[index];
    bar.set_note(item.name);
    for (auto& r : process_item(item, resolved, pending[p].methods, a.out, cache)) {
      const bool ok = r["status"] == "ok";
      summary.failures += !ok;
      write_json_file(
          (records_dir / record_file(item.name, r["method"].get<std::string>())).string(), r);
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
      record_key.emplace_back(index, method_index(r));
      summary.records.push_back(std::move(r));
    }
    bar.advance(1);
  }
  bar.finish();
  summary.loads = cache.loads();
  // One summary on rank 0: every rank's records and those kept, in the order of one process.
  std::vector<std::pair<std::pair<size_t, size_t>, nlohmann::json>> all;
  if (world > 1) {
    nlohmann::json shipped = nlohmann::json::array();
    for (size_t i = 0; i < summary.records.size(); ++i) {
      shipped.push_back({record_key[i].first, record_key[i].second, summary.records[i]});
    }
    const auto gathered = comm->all_gather(shipped.dump());
    if (rank != 0) return summary;  // rank 0 writes the summary
    for (const auto& part : gathered) {
      for (auto& entry : nlohmann::json::parse(part)) {
        all.emplace_back(std::make_pair(entry[0].get<size_t>(), entry[1].get<size_t>()),
                         std::move(entry[2]));
      }
    }
  } else {
    for (size_t i = 0; i < summary.records.size(); ++i) {
      all.emplace_back(record_key[i], std::move(summary.records[i]));
    }
  }
  for (auto& k : kept) all.push_back(std::move(k));
  std::stable_sort(all.begin(), all.end(),
                   [](const auto& x, const auto& y) { return x.first < y.first; });
  summary.records.clear();
  summary.failures = 0;
  for (auto& entry : all) {
    summary.failures += entry.second["status"] != "ok";
    summary.records.push_back(std::move(entry.second));
  }
  write_batch_summary(a.out, summary.records);
  if (folder) folder->commit();
  return summary;
}

}  // namespace lfnet::pipeline
