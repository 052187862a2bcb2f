// lfnet batch: reconstruct every acquisition folder, or evaluate every light-field folder, under
// a directory (pipeline::run_batch). One JSON record per item and method, a summary CSV; a bad
// item is recorded with its error and the others go on.
#include <spdlog/spdlog.h>

#include <sstream>

#include "command.h"
#include "dist_flags.h"
#include "flags.h"
#include "lfnet/core/error.h"
#include "lfnet/pipeline/batch.h"

namespace lfnet::app {

namespace {

struct BatchArgs {
  pipeline::BatchOptions options;
  std::string methods;         // comma-separated
  pipeline::DistOptions dist;  // ranks sharing the items (docs/distributed.md)
};

void run(BatchArgs& a) {
  auto comm = pipeline::join_job(a.dist);
  std::stringstream list(a.methods);
  for (std::string m; std::getline(list, m, ',');) {
    if (!m.empty()) a.options.methods.push_back(m);
  }
  const auto summary = pipeline::run_batch(a.options, comm);
  if (comm->rank() != 0) return;  // rank 0 reports
  spdlog::info(
      "batch: {} record(s), {} failed; summary in {}/summary.csv; {} model or dictionary file(s) "
      "read",
      summary.records.size(), summary.failures, a.options.out, summary.loads);
  LFNET_CHECK(summary.failures == 0, summary.failures, " of ", summary.records.size(),
              " item-method pair(s) failed; see ", a.options.out,
              "/summary.csv (the others are done)");
}

}  // namespace

void add_batch_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd = app.add_subcommand(
      "batch",
      "Reconstruct every acquisition folder, or evaluate every light-field folder, under a "
      "directory");
  auto a = std::make_shared<BatchArgs>();
  auto& o = a->options;
  input_path(cmd->add_option("--input,--in", o.in, "folder to search (recursively) for items"))
      ->required();
  output_folder(
      cmd->add_option("--out", o.out,
                      "output folder: reconstructions, records/, summary.csv, summary.json"))
      ->required();
  cmd->add_option("--methods", a->methods,
                  "comma-separated methods: " + pipeline::method_list() +
                      " (default net with --model, pinv without)");
  add_reconstruction_flags(
      cmd, {&o.model, nullptr, &o.phi, &o.device, &o.precision, &o.tile, &o.stride, nullptr,
            &o.self_ensemble, &o.self_ensemble_passes, &o.method_options});
  add_self_calibrate_flag(cmd, o.self_calibrate);
  add_dictionary_option(cmd, o.dictionary);
  add_mode_option(cmd, o.mode);  // of evaluations
  add_noise_option(cmd, o.noise);
  add_seed_option(cmd, o.seed);
  add_cfa_option(cmd, o.cfa);
  add_batch_option(cmd, o.batch);
  add_window_flag(cmd, o.window);
  add_post_filter_flag(cmd, o.post_filter);
  add_match_mean_flag(cmd, o.match_mean);
  add_demosaic_option(cmd, o.demosaic);
  add_flat_field_option(cmd, o.flat_field);
  add_force_flag(cmd, o.force);
  cmd->add_flag("--resume", o.resume,
                "continue the batch in --out: only the item-method pairs without a record of "
                "success are done (same options as the batch it continues)");
  add_budget_option(cmd, o.budget);
  add_dist_flags(cmd, a->dist);
  cmd->callback([a, cmd] {
    a->options.budget_precision = given_precision(cmd, a->options.precision);
    run(*a);
  });
}

}  // namespace lfnet::app
