// `lfnet report RUN_DIR`: the report of one `lfnet train` / `lfnet experiment` run folder.
#pragma once

#include <string>

namespace lfnet::app {

// True when `dir` is a run folder (it holds config.json).
bool is_run_folder(const std::string& dir);

// Writes `out` (default RUN_DIR/report.md) with the run's config, its training per stage with
// training curves (scripts/plot_training.py, matplotlib), its evaluations as tables with the
// margin over no-parallax, and the accuracy-against-time plot; figures go to `figures`
// (default RUN_DIR/figures).
void report_run(const std::string& run_dir, std::string out, std::string figures);

}  // namespace lfnet::app
