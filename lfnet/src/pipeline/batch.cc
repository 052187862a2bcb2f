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
#include "lfnet/pipeline/budget.h"
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
    // A sequence (frame_0 .. frame_{T-1}, docs/video.md) is one item, its frames no items.
    std::optional<std::string> problem;
    try {
      if (io::sequence_frames(dir.string()) > 0) problem = "";
    } catch (const std::exception& e) {
      problem = std::string(e.what());
    }
    if (!problem) problem = light_field_problem(dir);
    if (problem) {
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

namespace {

// One item of a batch, each of its methods a record: reconstructed (an acquisition folder),
// evaluated (a light-field folder) or failed with its reason.
class ItemProcessor {
 public:
  ItemProcessor(const BatchItem& item, const BatchOptions& options,
                const std::vector<std::string>& methods, const std::string& out_dir,
                ModelCache& cache)
      : item_(item),
        a_(options),
        methods_(methods),
        out_dir_(out_dir),
        cache_(cache),
        model_(options.model) {}

  std::vector<nlohmann::json> run() {
    if (item_.kind == "unreadable") {
      fail_all(item_.error);
    } else if (item_.kind == "reconstruct") {
      reconstruct();
    } else {
      evaluate();
    }
    return std::move(records_);
  }

 private:
  nlohmann::json failed(const std::string& method, const std::string& error) const {
    return {{"item", item_.name}, {"path", item_.path}, {"kind", item_.kind},
            {"method", method},   {"status", "error"},  {"error", without_source_locations(error)}};
  }
  void fail_all(const std::string& error) {
    for (const auto& method : methods_) records_.push_back(failed(method, error));
  }
  nlohmann::json ok(nlohmann::json record) const {
    record["item"] = item_.name;
    record["path"] = item_.path;
    record["kind"] = item_.kind;
    record["status"] = "ok";
    return record;
  }

  void reconstruct() {
    // What holds for every method, checked once per item: --phi against the model, and the
    // methods' options (checked for all methods at the start, read again here).
    nlohmann::json all_options;
    try {
      if (a_.budget > 0) {
        choose_model([&] {
          return budget_for_sensor(a_.budget, item_.path, a_.phi, a_.cfa, a_.device,
                                   a_.budget_precision);
        });
      }
      if (!model_.empty()) check_phi_argument(cache_.model(model_), a_.phi);
      all_options = method_options_argument(a_.method_options, methods_);
    } catch (const std::exception& e) {
      return fail_all(e.what());
    }
    for (const auto& method : methods_) {
      try {
        records_.push_back(reconstruct_with(method, all_options));
      } catch (const std::exception& e) {
        records_.push_back(failed(method, e.what()));
      }
    }
  }

  nlohmann::json reconstruct_with(const std::string& method, const nlohmann::json& all_options) {
    ReconstructRequest q;
    q.sensor = item_.path;
    q.method = method;
    q.model = model_;
    q.dictionary = a_.dictionary;
    if (all_options.contains(method)) {
      q.method_options = nlohmann::json{{method, all_options[method]}}.dump();
    }
    q.options.stride = a_.stride;
    q.options.batch = a_.batch;
    q.options.window = a_.window;
    q.post_filter = a_.post_filter;
    q.match_mean = a_.match_mean;
    q.flat_field = a_.flat_field;
    q.demosaic = a_.demosaic;
    q.self_ensemble = a_.self_ensemble;
    q.self_ensemble_passes = a_.self_ensemble_passes;
    q.self_calibrate = a_.self_calibrate;
    q.device = a_.device;
    q.precision = precision();
    q.tile = a_.tile;
    q.coded = true;  // as reconstruct: a grey light field in 16-bit codes
    auto r = reconstruct_acquisition(q, {}, &cache_);
    if (budget_) record_budget(*budget_, r.record);
    const std::string target = (fs::path(out_dir_) / item_.name / method).string();
    OutputFolderPolicy policy;
    policy.inputs = batch_inputs(a_);
    policy.inputs.push_back(item_.path);
    policy.force = a_.resume;  // an output without its record is an unfinished attempt
    write_reconstruction(r, target, policy, /*end_to_end=*/false);  // the batch's, not the item's
    auto record = ok(r.record);
    record["output"] = target;
    return record;
  }

  // evaluate: simulate with the model's Phi (or --phi), reconstruct, score.
  void evaluate() {
    try {
      read_truth();
    } catch (const std::exception& e) {
      return fail_all(e.what());
    }
    for (const auto& method : methods_) {
      try {
        records_.push_back(evaluate_with(method));
      } catch (const std::exception& e) {
        records_.push_back(failed(method, e.what()));
      }
    }
  }

  void read_truth() {
    if (a_.budget > 0) {
      choose_model([&] {
        return budget_for_light_field(a_.budget, light_field_pixels(item_.path, "", ""), a_.phi,
                                      a_.cfa, a_.device, a_.budget_precision);
      });
    }
    optics::PhiSpec spec;
    if (!model_.empty()) {
      const auto& model = cache_.model(model_);
      spec = optics::PhiSpec::from_json(model.phi, model_ + ":$.phi");
      check_phi_argument(model, a_.phi);
      place_network(model, a_.device, precision());
      use_model(context_, model);
      patch_ = model.network.patch_grid();
    } else {
      LFNET_CHECK_AS(ConfigError, !a_.phi.empty(),
                     "evaluating light-field folders needs --model or --phi");
      spec = phi_from_argument(a_.phi);
    }
    phi_ = optics::make_phi(spec);
    context_.phi = phi_.get();
    context_.dictionary = a_.dictionary;
    context_.cache = &cache_;
    context_.method_options = method_options_argument(a_.method_options, methods_);
    context_.self_ensemble = a_.self_ensemble;
    context_.self_ensemble_passes = a_.self_ensemble_passes;
    context_.self_calibrate = a_.self_calibrate;
    context_.tile = a_.tile;
    LightFieldSources sources;
    sources.light_fields = {item_.path};
    // As evaluate: a grey truth of 16-bit views in 16-bit codes.
    truths_ = load_sources(sources, phi_->rows(), phi_->cols(), false, !a_.cfa.empty(),
                           a_.cfa.empty(), phi_->frames());
    if (!a_.cfa.empty()) cfa_ = optics::ColourFilterArray::parse(a_.cfa);
  }

  nlohmann::json evaluate_with(const std::string& method) {
    if (!model_.empty() && recon::needs_network(method)) {
      cache_.model(model_).check_cfa(cfa_ ? cfa_->pattern() : "");
    }
    auto o = make_eval_options(a_.mode, a_.noise, a_.seed, a_.stride, a_.batch, a_.window, patch_);
    o.cfa = cfa_;
    // A colour net demosaics inside itself: --demosaic is for the other methods.
    check_demosaic_argument(a_.demosaic, cfa_.has_value(), false, method);
    o.demosaic = a_.demosaic;
    context_.coded = o.reconstruct.coded = !cfa_;  // as evaluate: a grey estimate in 16-bit codes
    auto record = ok(evaluate_method(truths_[0], method, context_, o, nullptr, false));
    add_frame_scores(record, phi_->frames(), item_.path);
    if (budget_) record_budget(*budget_, record);
    const auto needs = recon::find_method(method).needs();
    if (needs == recon::MethodNeeds::kNetwork) record["model"] = model_;
    if (needs == recon::MethodNeeds::kDictionary) record["model"] = a_.dictionary;
    return record;
  }

  // The precision the model runs in: the budget's choice's, else --precision.
  nn::Precision precision() const { return budget_ ? budget_->setting.precision : a_.precision; }

  // --budget: this item's model, chosen for its camera and size.
  template <typename Choose>
  void choose_model(const Choose& choose) {
    budget_ = choose();
    model_ = budget_->path;
  }

  const BatchItem& item_;
  const BatchOptions& a_;
  const std::vector<std::string>& methods_;
  const std::string& out_dir_;
  ModelCache& cache_;
  std::string model_;                   // --model, or the one the budget chose
  std::optional<BudgetChoice> budget_;  // with --budget
  std::vector<nlohmann::json> records_;
  // An evaluated item's truth, camera and method context.
  std::vector<NamedLightField> truths_;
  MethodContext context_;
  std::unique_ptr<optics::Phi> phi_;
  std::optional<nn::PatchShape> patch_;           // the model's, when there is one
  std::optional<optics::ColourFilterArray> cfa_;  // --cfa, inline once the batch has read it
};

}  // namespace

std::vector<nlohmann::json> process_item(const BatchItem& item, const BatchOptions& a,
                                         const std::vector<std::string>& methods,
                                         const std::string& out_dir, ModelCache& cache) {
  return ItemProcessor(item, a, methods, out_dir, cache).run();
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
  if (a.budget > 0) options["budget"] = a.budget;
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

namespace {

// lfnet batch as a controller: check() reads the methods, their options, the colour filter
// array, the output folder and the items before any work; run() makes the folder, takes this
// rank's share of the pairs still to do and, on rank 0, writes the summary of every rank's.
class Batch {
 public:
  Batch(const BatchOptions& options, std::shared_ptr<dist::Communicator> comm)
      : a_(options),
        comm_(comm ? std::move(comm) : std::make_shared<dist::LocalCommunicator>()),
        rank_(comm_->rank()),
        world_(comm_->world_size()),
        resolved_(options) {}

  void check() {
    methods_ = a_.methods;
    if (a_.budget > 0) {
      check_budget_request(
          {!a_.model.empty(), !methods_.empty() && methods_ != std::vector<std::string>{"net"},
           a_.self_ensemble, a_.self_calibrate, a_.mode != optics::SimulationMode::kSensor});
      methods_ = {"net"};
    }
    if (methods_.empty()) methods_ = {a_.model.empty() ? "pinv" : "net"};
    for (const auto& m : methods_) {
      try {
        (void)recon::find_method(m);
      } catch (const ConfigError& e) {
        throw ConfigError(std::string("--methods: ") + e.what());
      }
    }
    // Read once: the items take them inline, not from a file again.
    const auto method_options = method_options_argument(a_.method_options, methods_);
    resolved_.method_options = method_options.empty() ? "" : method_options.dump();
    // --cfa, or the one a calibrated Phi's folder names.
    if (const auto cfa = cfa_of_arguments(a_.cfa, a_.phi)) {
      cfa->check_demosaicable();
      resolved_.cfa = cfa->to_json().dump();
    }
    manifest_ = batch_manifest(a_, methods_);
    check_output();
    items_ = discover_items(a_.in);
    LFNET_CHECK_AS(ConfigError, !items_.empty(), "no acquisition folder (with ", io::kSidecarName,
                   ") and no light-field folder under ", a_.in);
    LFNET_CHECK_AS(ConfigError, a_.noise >= 0, "--noise must be >= 0");
    recon::check_ensemble_passes(a_.self_ensemble, a_.self_ensemble_passes);
    if (a_.self_ensemble) {
      LFNET_CHECK_AS(ConfigError, !a_.model.empty(),
                     "--self-ensemble applies to --method net with a whole-image model: pass "
                     "--model");
      const auto& model = cache_.model(a_.model);
      for (const auto& m : methods_) recon::check_self_ensemble(m, model.net, model.script.get());
    }
  }

  BatchSummary run() {
    make_folder();
    plan();
    BatchSummary summary = process_mine();
    summary.loads = cache_.loads();
    if (!gather(summary)) return summary;  // rank 0 writes the summary
    write_batch_summary(a_.out, summary.records);
    if (folder_) folder_->commit();
    return summary;
  }

 private:
  // ((item, method), record): where a record sits in the summary of one process.
  using Keyed = std::pair<std::pair<size_t, size_t>, nlohmann::json>;
  struct Pending {
    size_t item;
    std::vector<std::string> methods;
  };

  void check_output() {
    policy_.force = a_.force;
    policy_.inputs = batch_inputs(a_);
    policy_.inputs.push_back(a_.in);
    if (a_.resume) return check_resumable(a_, manifest_);
    try {
      check_output_folder(a_.out, policy_);
    } catch (const ConfigError& e) {
      std::error_code ec;
      if (!fs::is_regular_file(fs::path(a_.out) / "batch.json", ec)) throw;
      throw ConfigError(std::string(e.what()) + "; it holds a batch: --resume continues it");
    }
  }

  void make_folder() {
    if (rank_ == 0) folder_ = std::make_unique<RunFolder>(a_.out, policy_, a_.resume);
    // The other ranks write only once rank 0 has checked and made the folder (when it is
    // shared), and rank 0 writes into it only once they have checked it.
    comm_->barrier();
    if (rank_ == 0 && !a_.resume) {
      write_json_file((fs::path(a_.out) / "batch.json").string(), manifest_);
    }
    records_dir_ = fs::path(a_.out) / "records";
    fs::create_directories(records_dir_);
  }

  // The pairs still to do (all of them unless resumed), the records of those done, and this
  // rank's share: pending items r, r + W, r + 2W, ... (neighbours in the list, often alike in
  // size, go to different ranks).
  void plan() {
    int64_t reconstruct = 0;
    for (const auto& it : items_) reconstruct += it.kind == "reconstruct";
    spdlog::info("batch: {} item(s) under {} ({} to reconstruct, {} to evaluate), methods {}",
                 items_.size(), a_.in, reconstruct, items_.size() - reconstruct,
                 join(methods_, ","));
    for (size_t i = 0; i < items_.size(); ++i) {
      Pending p{i, {}};
      for (size_t m = 0; m < methods_.size(); ++m) {
        auto done = a_.resume
                        ? finished_record(records_dir_ / record_file(items_[i].name, methods_[m]))
                        : std::nullopt;
        if (done) {
          kept_.emplace_back(std::make_pair(i, m), std::move(*done));
        } else {
          p.methods.push_back(methods_[m]);
        }
      }
      if (!p.methods.empty()) pending_.push_back(std::move(p));
    }
    if (a_.resume) {
      spdlog::info("batch: resumed; {} of {} item-method pair(s) done before, {} item(s) to do",
                   kept_.size(), items_.size() * methods_.size(), pending_.size());
    }
    for (size_t i = static_cast<size_t>(rank_); i < pending_.size();
         i += static_cast<size_t>(world_)) {
      mine_.push_back(i);
    }
    if (world_ > 1) {
      spdlog::info("batch: {} rank(s), rank 0 takes {} item(s)", world_, mine_.size());
    }
  }

  BatchSummary process_mine() {
    BatchSummary summary;
    ProgressBar bar("batch", static_cast<int64_t>(mine_.size()), "items");
    for (size_t p : mine_) {
      const size_t index = pending_[p].item;
      const auto& item = items_[index];
      bar.set_note(item.name);
      for (auto& r : process_item(item, resolved_, pending_[p].methods, a_.out, cache_)) {
        summary.failures += r["status"] != "ok";
        write_json_file(
            (records_dir_ / record_file(item.name, r["method"].get<std::string>())).string(), r);
        if (folder_) folder_->commit();  // a record lasts: the batch keeps its folder from now on
        log_record(item, r);
        record_key_.emplace_back(index, method_index(r));
        summary.records.push_back(std::move(r));
      }
      bar.advance(1);
    }
    bar.finish();
    return summary;
  }

  static void log_record(const BatchItem& item, const nlohmann::json& r) {
    const auto method = r["method"].get<std::string>();
    if (r["status"] != "ok") {
      spdlog::warn("{} {}: {}", item.name, method, r["error"].get<std::string>());
    } else if (r.contains("psnr_db")) {
      spdlog::info("{} {}: PSNR {:.2f} dB, SSIM {:.4f}, {:.2f} s", item.name, method,
                   r["psnr_db"].is_null() ? INFINITY : r["psnr_db"].get<double>(),
                   r["ssim"].get<double>(), r["seconds"].get<double>());
    } else {
      spdlog::info("{} {}: {:.2f} s -> {}", item.name, method, r["seconds"].get<double>(),
                   r["output"].get<std::string>());
    }
  }

  size_t method_index(const nlohmann::json& r) const {
    const auto name = r["method"].get<std::string>();
    return static_cast<size_t>(std::find(methods_.begin(), methods_.end(), name) -
                               methods_.begin());
  }

  // One summary on rank 0: every rank's records and those kept, in the order of one process.
  // False on the other ranks, which have no summary to write.
  bool gather(BatchSummary& summary) {
    std::vector<Keyed> all;
    if (world_ > 1) {
      nlohmann::json shipped = nlohmann::json::array();
      for (size_t i = 0; i < summary.records.size(); ++i) {
        shipped.push_back({record_key_[i].first, record_key_[i].second, summary.records[i]});
      }
      const auto gathered = comm_->all_gather(shipped.dump());
      if (rank_ != 0) return false;
      for (const auto& part : gathered) {
        for (auto& entry : nlohmann::json::parse(part)) {
          all.emplace_back(std::make_pair(entry[0].get<size_t>(), entry[1].get<size_t>()),
                           std::move(entry[2]));
        }
      }
    } else {
      for (size_t i = 0; i < summary.records.size(); ++i) {
        all.emplace_back(record_key_[i], std::move(summary.records[i]));
      }
    }
    for (auto& k : kept_) all.push_back(std::move(k));
    std::stable_sort(all.begin(), all.end(),
                     [](const auto& x, const auto& y) { return x.first < y.first; });
    summary.records.clear();
    summary.failures = 0;
    for (auto& entry : all) {
      summary.failures += entry.second["status"] != "ok";
      summary.records.push_back(std::move(entry.second));
    }
    return true;
  }

  const BatchOptions& a_;
  std::shared_ptr<dist::Communicator> comm_;
  const int64_t rank_, world_;
  BatchOptions resolved_;  // the options the items take: method options and CFA inline
  std::vector<std::string> methods_;
  nlohmann::json manifest_;
  OutputFolderPolicy policy_;
  std::vector<BatchItem> items_;
  ModelCache cache_;                   // every item shares one read of the model and the dictionary
  std::unique_ptr<RunFolder> folder_;  // rank 0 makes it; the others write into it
  fs::path records_dir_;
  std::vector<Pending> pending_;
  std::vector<Keyed> kept_;
  std::vector<size_t> mine_;                           // this rank's indices into pending_
  std::vector<std::pair<size_t, size_t>> record_key_;  // (item, method) of every record
};

}  // namespace

BatchSummary run_batch(const BatchOptions& a, std::shared_ptr<dist::Communicator> comm) {
  Batch batch(a, std::move(comm));
  batch.check();
  return batch.run();
}

}  // namespace lfnet::pipeline
