// `lfnet report`: docs/RESULTS.md and its figures from result records, or the report of one run
// folder (docs/experiments.md, "Reports").
#pragma once

#include <string>

namespace lfnet::pipeline {

// True when `dir` is a run folder (it holds config.json).
bool is_run_folder(const std::string& dir);

// RESULTS_DIR holds one folder per section: section.json (title, text, the command that made
// the records, the paper's numbers for the same settings, figures to draw) and records.jsonl
// (lfnet evaluate records). Writes `out` (Markdown) with a table per section, margins, per-view
// PSNR heatmaps, pictures, sweeps and the accuracy-against-time plot (figures in `figures`,
// default images/results beside `out`), and the paper's claims beside ours.
void write_results_report(const std::string& results_dir, const std::string& out,
                          const std::string& figures = "");

// Writes `out` (default RUN_DIR/report.md) with the run's config, its training per stage with
// training curves, its evaluations as tables with the margin over no-parallax, and the
// accuracy-against-time plot; figures go to `figures` (default `figures` beside `out`).
void write_run_report(const std::string& run_dir, std::string out = "", std::string figures = "");

}  // namespace lfnet::pipeline
