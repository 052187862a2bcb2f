// Coded capture into an acquisition folder: what `lfnet simulate` writes and `lfnet
// reconstruct` reads (docs/acquisition.md, "The acquisition folder").
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>
#include <utility>

#include "lfnet/core/light_field.h"
#include "lfnet/optics/calibration.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "lfnet/optics/sensor.h"

namespace lfnet::pipeline {

// One simulation: a light field coded by a Phi, with sensor effects.
struct SimulateRequest {
  LightField lf;  // (C, U, V, H, W): the window the Phi codes, grey or colour
  const optics::Phi* phi = nullptr;
  optics::SensorOptions effects;  // noise and the rest (validated by the caller)
  // The camera's error against `phi` (sensor mode only): the image it takes, recorded as
  // sensor.json's camera_error; a reconstruction is told `phi`.
  optics::CalibrationError camera_error;
  // A single colour sensor (sensor mode, a colour light field): each pixel measures its N
  // values of the colours its filter passes, one sensor image of N channels; recorded as
  // sensor.json's cfa.
  std::optional<optics::ColourFilterArray> cfa;
  optics::SimulationMode mode = optics::SimulationMode::kSensor;
  uint64_t seed = 0;                // noise seed
  int64_t patch = 9;                // per_patch mode: the patch grid's side
  int64_t stride = 5;               // and stride
  nlohmann::json views = nullptr;   // recorded: the window in the source grid
  nlohmann::json source = nullptr;  // recorded: where the light field came from
};

// Writes the acquisition of `r` into the folder `dir` (which exists; output policy is the
// caller's): the sensor image files (sensor mode) or measurements.f32 (per_patch, written in
// bands of patch rows with a progress bar), then sensor.json, which it returns.
nlohmann::json write_acquisition(const SimulateRequest& r, const std::string& dir);

// Where `lfnet simulate` takes its light field from.
struct SimulateSource {
  std::string lf;      // a light-field folder
  std::string scene;   // or a procedural scene spec to render
  std::string white;   // or "HxW": a uniform white light field of that size, a white frame
  std::string views;   // angular window R0:R1,C0:C1, 1-based ("" = the central 5 x 5)
  std::string orient;  // reorientation of the folder's angular axes (docs/conventions.md)
  std::string layout;  // file-naming pattern of the folder (io::parse_layout)
  bool color = false;  // every colour channel (else the grey luma)
};

// The light field to code and a record of where it came from.
struct SimulateInput {
  LightField lf;                                // windowed, grey unless color
  nlohmann::json source;                        // kind and absolute path (and orient, layout)
  nlohmann::json views;                         // the window in the source grid, 1-based inclusive
  std::optional<nlohmann::json> scene_effects;  // a scene's own sensor block, if it names one
};

// Reads (or renders) and windows the light field of `source`. For a camera of `frames` > 1
// sub-frames (docs/video.md), the stacked light field of a sequence folder's frames, each
// windowed, or a still source's held in every frame; a sequence folder needs as many frames.
SimulateInput load_simulate_input(const SimulateSource& source, int64_t frames = 1);

// The window size `views` selects ("" = 5 x 5), for a Phi without a light field to look at.
std::pair<int64_t, int64_t> window_size(const std::string& views);

// The Phi of `arg` (NAME[:N], a spec file, a calibrated-Phi folder, a model file) on a window of
// rows x cols views; a file that codes another window is a ConfigError.
optics::PhiSpec phi_for_window(const std::string& arg, int64_t rows, int64_t cols);

// The sensor effects of a simulation: the effects file (or else the scene's own sensor block),
// then `noise` (>= 0: the Gaussian sigma, replacing the file's); validated.
optics::SensorOptions simulation_effects(const std::string& effects_file, double noise,
                                         const SimulateInput& input, const std::string& scene_path);

// How much each piece of the camera can recover, as text: the spec, the ASP table, singular
// values and condition numbers (by pixel phase for periodic models).
std::string describe_phi(const optics::Phi& phi);

// lfnet simulate: what to code, with which camera and sensor, into which folder; or only the
// Phi described or its weights drawn.
struct SimulateOptions {
  SimulateSource source;      // the light field (or scene, or white frame), window, orientation
  std::string phi = "asp:2";  // NAME[:N], a Phi spec, a calibrated-Phi folder or a model
  optics::SimulationMode mode = optics::SimulationMode::kSensor;
  double noise = -1;  // < 0: not given
  uint64_t seed = 0;
  std::string out;
  std::string effects;       // EFFECTS.json
  std::string camera_error;  // JSON or a file (optics/calibration.h)
  std::string cfa;  // a Bayer pattern or JSON, inline or a file (optics/cfa.h); implies colour
  int64_t stride = 5;
  int64_t patch = 9;
  bool force = false;
  bool describe = false;     // describe the Phi (SimulateResult::description)
  std::string plot_weights;  // folder for the Phi's angular-response figure
};

struct SimulateResult {
  std::string description;   // with `describe`: describe_phi of the camera
  std::string weights_file;  // with `plot_weights`: the PNG drawn
  bool simulated = false;    // an acquisition folder was written to `out`
};

// Checks every argument and output before any work, then draws and describes the Phi and writes
// the acquisition folder, as asked.
SimulateResult simulate(const SimulateOptions& options);

}  // namespace lfnet::pipeline
