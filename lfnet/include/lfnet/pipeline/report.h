// `lfnet report`: docs/RESULTS.md and its figures from result records, or the report of one run
// folder (docs/experiments.md, "Reports").
#pragma once

#include <string>

namespace lfnet::pipeline {

// True when `dir` is a run folder (it holds config.json).
bool is_run_folder(const std::string& dir);

// The time the results report's front page weighs accuracy against: the whole command as its
// user waits for it (records' end_to_end_seconds), or the reconstruction alone (seconds).
enum class ParetoTime { kEndToEnd, kReconstruction };

// RESULTS_DIR holds one folder per section: section.json (title, text, the command that made
// the records, the paper's numbers for the same settings, figures to draw) and records.jsonl
// (lfnet evaluate records). Writes `out` (Markdown) with a table per section, margins, per-view
// PSNR heatmaps, pictures and sweeps (figures in `figures`, default images/results beside
// `out`), and the paper's claims beside ours on its own scene, per aperture. Its front page
// weighs accuracy against `time` on the paper's scene at 5 cm: a table and the Pareto plot.
void write_results_report(const std::string& results_dir, const std::string& out,
                          const std::string& figures = "", ParetoTime time = ParetoTime::kEndToEnd);

// Writes `out` (default RUN_DIR/report.md) with the run's config, its training per stage with
// training curves, its evaluations as tables with the margin over no-parallax, and the
// accuracy-against-time plot; figures go to `figures` (default `figures` beside `out`).
void write_run_report(const std::string& run_dir, std::string out = "", std::string figures = "");

}  // namespace lfnet::pipeline
