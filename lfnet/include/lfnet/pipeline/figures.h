// Figures of lfnet's reports, drawn by scripts/figures.py (Debian's python3-matplotlib) from JSON
// specs: a PNG for the Markdown and an SVG beside it. docs/figures.md lists the kinds.
#pragma once

#include <torch/types.h>

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

#include "lfnet/core/output.h"
#include "lfnet/optics/phi.h"

namespace lfnet::pipeline {

// One result on the accuracy-against-time plot.
struct ParetoPoint {
  std::string method;        // colours the point
  std::string variant;       // names a second model of one method (e.g. "net (paper-scale)")
  int64_t n = 0;             // the camera: measurements per pixel; sets the marker
  int64_t stride = 0;        // a runtime setting, written beside the point
  bool whole_image = false;  // reconstructed without patches (the lfnet architecture): no stride
  double seconds = 0;
  double psnr_db = 0;
  bool front = false;  // on the Pareto front (no other point is both faster and better)
};

// The point of an evaluation record (docs/reconstruction.md, "lfnet evaluate"): its method,
// variant, measurements, stride, whole_image, seconds (0 when missing) and psnr_db.
ParetoPoint pareto_point(const nlohmann::json& record);

// Marks the Pareto front: a point is on it when every faster point has a lower PSNR.
void mark_pareto_front(std::vector<ParetoPoint>& points);

// The points as a "pareto" figure spec.
nlohmann::json pareto_spec(const std::vector<ParetoPoint>& points, const std::string& title,
                           const std::string& xlabel = "reconstruction time (s, log scale)");

// Where scripts/figures.py is: $LFNET_SCRIPTS, the source tree the program was built from, or
// scripts/ under the current folder; "" when none has it.
std::string figures_script();

// Reads the JSON records of a .jsonl file (blank lines skipped); a bad line is an IoError
// naming the file and line.
std::vector<nlohmann::json> read_jsonl(const std::string& path);

// The figures of one report: specs collected, then drawn in one run of the script.
class FigureSet {
 public:
  // PNG and SVG files go to `folder`; the images the specs refer to, to folder/data.
  explicit FigureSet(std::string folder);

  // A figure spec (scripts/figures.py); its "stem" is a file name inside the folder.
  void add(nlohmann::json spec);
  // Writes a grey (H, W) image in [0, 1] as a 16-bit PNG for a spec; returns its path relative to
  // the folder, as specs hold it.
  std::string image(const std::string& name, const torch::Tensor& image) const;
  bool empty() const { return specs_.empty(); }

  // Draws every figure added, from the specs written to folder/`spec_name`; returns "" or why
  // the figures are missing (no python3 or matplotlib, no script), for the report to say.
  std::string draw(const std::string& spec_name = "figures.json") const;
  // Training curves of a run's training.jsonl into folder/STEM.{png,svg}; "" or why not.
  std::string training(const std::string& log, const std::string& stem) const;

 private:
  std::string folder_;
  std::vector<nlohmann::json> specs_;
};

// The angular responses of a Phi (optics::weight_tiles) as DIR/NAME-nN.png and .svg, with their
// spec beside them (NAME-nN.json); returns the PNG's path. The files go through the output policy
// (core/output.h): DIR apart from `policy.inputs`, an existing file replaced only with
// `policy.force`, the three written whole. A figure that cannot be drawn is an IoError that says
// why.
std::string plot_weights(const optics::Phi& phi, const std::string& dir,
                         const OutputFolderPolicy& policy = {});

}  // namespace lfnet::pipeline
