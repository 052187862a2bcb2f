// Reconstructing one acquisition (an lfnet sensor folder or a camera's own sensor images)
// with any method, and writing the result as a light-field folder.
#pragma once

#include <nlohmann/json.hpp>

#include <string>

#include "lfnet/core/light_field.h"
#include "lfnet/core/output.h"
#include "lfnet/io/viewer.h"
#include "lfnet/nn/network.h"
#include "lfnet/pipeline/models.h"
#include "lfnet/recon/fully_convolutional.h"
#include "lfnet/recon/reconstruct.h"

namespace lfnet::pipeline {

// What `lfnet reconstruct` does for one acquisition.
struct ReconstructRequest {
  // An acquisition folder (sensor.json with sensor.tif or measurements.f32), or a camera's own
  // sensor image: one file of N channels per colour channel, comma-separated, with `phi`.
  std::string sensor;
  std::string phi;  // Phi spec for plain images: NAME[:N] or a JSON file ("" = the model's)
  std::string method = "net";
  std::string model;           // checkpoint for net, ae, cnn
  std::string dictionary;      // dictionary file for dict
  std::string method_options;  // --method-options: JSON or file, keyed by method
  std::string flat_field;      // the camera's white frame (read_flat_field); "" none
  // The colour filter array a plain sensor image was taken behind (--cfa: a pattern, JSON or a
  // file; "" none, or the one the camera's calibrated Phi names); an acquisition records its own.
  std::string cfa;
  // How a patch method's views of a colour filter array's sensor image are demosaiced.
  optics::Demosaic demosaic = optics::Demosaic::kBilinear;
  recon::ReconstructOptions options;  // stride (sensor mode), batch, window
  bool match_mean = false;            // scale the measurements to the training mean
  bool post_filter = false;           // suppress artefacts with the stride's period
  std::string device = "cpu";         // cpu or cuda[:K], for checkpoints' networks
  recon::CnnMode cnn_mode = recon::CnnMode::kPatches;  // or kFull: the CNN branch in tiles
  int64_t tile = 0;                  // tile of cnn_mode full and of lfnet models (0: 128, 256)
  bool self_ensemble = false;        // lfnet models: average over the Phi's mirror images
  int64_t self_ensemble_passes = 0;  // at most this many of them (0: all)
  bool self_calibrate = false;       // lfnet models: estimate the camera's angular shift
  nn::Precision precision = nn::Precision::kFloat32;  // of the CNN branch (lfnet: the U-Net)
  // The sensor's Gaussian noise sigma (relative to white) for noise-aware models; negative:
  // the noise_sigma that the acquisition's sensor.json records, else 0.
  double noise_sigma = -1;
  // Hold a grey light field in 16-bit codes (core/light_field.h), what its files hold: half
  // the memory of float32 (`lfnet reconstruct` and `batch`). Not with post_filter or a colour
  // filter array, which stay float32.
  bool coded = false;
};

// A reconstruction and its record (method, model, sensor, stride, seconds, phi, mode, shape).
struct Reconstruction {
  LightFieldViews lf;  // float32 or 16-bit codes
  nlohmann::json record;
};

// Reconstructs one acquisition. `progress` (optional) gets (patches done, patches in all), or
// for a whole-image network (sensor pixels done, sensor pixels in all); with a `cache`, the model
// or dictionary is read once and reused by later calls.
Reconstruction reconstruct_acquisition(const ReconstructRequest& request,
                                       const recon::ProgressCallback& progress = {},
                                       ModelCache* cache = nullptr);

// Writes an estimate's views, previews (grid, EPIs) and viewer (index.html) into `dir`; a
// stacked sequence of `frames` > 1 frames (docs/video.md) as one such folder per frame,
// dir/frame_t, each with its rows of page.truth and of the record's per-view table.
void write_estimate(const LightFieldViews& lf, const std::string& dir, const io::ViewerPage& page,
                    int64_t frames = 1);

// Writes a reconstruction as a light-field folder with previews and reconstruction.json, by
// the output-folder policy (core/output.h). With `end_to_end`, the record written gets
// end_to_end_seconds: the process's time from its start up to it, every other output written
// (a command's own; a batch's items leave it out).
void write_reconstruction(const Reconstruction& r, const std::string& out,
                          const OutputFolderPolicy& policy, bool end_to_end = true);

}  // namespace lfnet::pipeline
