// `lfnet export`: a checkpoint's network as a TorchScript file that LibTorch and Python run
// without lfnet (docs/export.md); `lfnet phi export`: a camera's Phi as a calibrated-Phi folder
// (docs/acquisition.md, "Calibrated Phi").
#pragma once

#include <cstdint>
#include <string>

namespace lfnet::pipeline {

struct ExportRequest {
  std::string model;  // a checkpoint
  std::string out;    // the TorchScript file to write
  // Patches on which the file is compared with the checkpoint (0: none); a net of the lfnet
  // architecture is compared on one random sensor image in several tiles instead.
  int64_t check = 256;
  bool force = false;  // replace an existing file
};

struct ExportResult {
  std::string phi;       // the Phi's label, e.g. asp:2
  std::string branches;  // net, ae or cnn; "lfnet" for the lfnet architecture
  int64_t phases = 0;
  double megabytes = 0;       // the file's size
  double max_difference = 0;  // max |exported - checkpoint| over the check inputs
  std::string compared;       // what was compared, e.g. "256 patches"; empty without a check
};

// Writes the file, reads it back and compares it with the checkpoint's net on `check` random
// patches measured through the net's own Phi; a difference over 1e-5 is a NumericalError. An
// exported file given as the model, or a checkpoint whose Phi does not fit its network, is an
// error before anything is written.
ExportResult export_model(const ExportRequest& request);

struct PhiExportRequest {
  std::string phi;           // NAME[:N], a Phi spec, a calibrated-Phi folder or a model
  std::string out;           // the folder to write
  std::string grid = "5x5";  // the views U x V a NAME[:N] Phi codes
  bool force = false;        // replace an existing folder
  bool printable = false;    // each measurement's code as an 8-bit image too (mask_<n>.png)
};

struct PhiExportResult {
  std::string label;  // e.g. asp:2
  int64_t measurements = 0, rows = 0, cols = 0, period = 0;
  bool printable = false;    // mask_<n>.png written (asked, or a learned mask or aperture)
  bool code_file = false;    // code.json written: the learned code's physical parameters
  std::string missing_code;  // a learned code whose parameters the model does not hold: its kind
};

// Writes the Phi's weights (phi.json and one image per measurement), reads the folder back and
// compares it weight for weight (a difference is a NumericalError; nothing is left behind).
PhiExportResult export_phi(const PhiExportRequest& request);

}  // namespace lfnet::pipeline
