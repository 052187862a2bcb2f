// `lfnet export`: a checkpoint's network as a TorchScript file that LibTorch and Python run
// without lfnet (docs/export.md).
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

}  // namespace lfnet::pipeline
