// lfnet report: docs/RESULTS.md and its figures from result records, or the report of one run
// folder (pipeline/report.h).
#include <map>

#include "command.h"
#include "lfnet/pipeline/report.h"

namespace lfnet::app {

namespace {
struct ReportArgs {
  std::string results = "results";
  std::string out = "docs/RESULTS.md";
  std::string figures;  // default: images/results beside --out (a run: figures beside --out)
  pipeline::ParetoTime pareto_time = pipeline::ParetoTime::kEndToEnd;
};
}  // namespace

void add_report_command(CLI::App& app, const GlobalOptions&) {
  auto* cmd =
      app.add_subcommand("report", "Write docs/RESULTS.md and its figures from result records");
  auto a = std::make_shared<ReportArgs>();
  input_path(cmd->add_option("results", a->results,
                             "folder of result sections (default results), or the run folder of an "
                             "lfnet train / experiment"));
  auto* out =
      output_file(cmd->add_option("--out", a->out,
                                  "the Markdown file to write (default docs/RESULTS.md; for a run "
                                  "folder RUN/report.md)"));
  cmd->add_option("--figures", a->figures,
                  "folder for the figures, PNG and SVG (default images/results beside --out)");
  const std::map<std::string, pipeline::ParetoTime> times = {
      {"end-to-end", pipeline::ParetoTime::kEndToEnd},
      {"reconstruction", pipeline::ParetoTime::kReconstruction}};
  cmd->add_option("--pareto-time", a->pareto_time,
                  "the time the front page weighs accuracy against: end-to-end (the whole "
                  "command, default) or reconstruction (the reconstruction alone)")
      ->transform(CLI::CheckedTransformer(times, CLI::ignore_case));
  cmd->callback([a, out] {
    if (pipeline::is_run_folder(a->results)) {
      pipeline::write_run_report(a->results, out->count() > 0 ? a->out : "", a->figures);
    } else {
      pipeline::write_results_report(a->results, a->out, a->figures, a->pareto_time);
    }
  });
}

}  // namespace lfnet::app
