// Simulate-then-reconstruct evaluation of a method on a light field with known truth.
#pragma once

#include <torch/types.h>
#include <nlohmann/json.hpp>

#include <cstdint>
#include <optional>
#include <string>

#include "lfnet/core/light_field.h"
#include "lfnet/optics/calibration.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "lfnet/optics/sensor.h"
#include "lfnet/recon/reconstruct.h"

namespace lfnet::eval {

// Options of one evaluation.
struct EvalOptions {
  // sensor: crops of one sensor image; per_patch: the paper's protocol.
  optics::SimulationMode mode = optics::SimulationMode::kSensor;
  optics::SensorOptions effects;          // noise and other sensor effects; none by default
  uint64_t seed = 0;                      // noise seed
  recon::ReconstructOptions reconstruct;  // stride, patch size, batch, window
  // Noise-aware methods are told the noise estimated from the sensor image
  // (optics/noise_estimate.h) instead of the simulation's: a camera whose noise is unknown.
  bool estimate_noise = false;
  // The camera's error against the Phi the method is told (sensor mode; optics/calibration.h):
  // the sensor is simulated by the perturbed camera, the method reconstructs with the nominal
  // Phi. Empty: the camera is the Phi.
  optics::CalibrationError camera_error;
  // The camera's flat field (H, W) (optics::flat_field_gain; sensor mode): the sensor image's
  // measurements are divided by it before the method runs. Undefined: none.
  torch::Tensor flat_field;
  // A single colour sensor behind this colour filter array (sensor mode, a colour truth): the
  // method reconstructs the mosaicked light field, each of its views then demosaiced; the
  // record scores colour (psnr_db, ssim) and luma (luma_psnr_db).
  std::optional<optics::ColourFilterArray> cfa;
  // How those views are demosaiced (a colour net demosaics inside itself, network.demosaic).
  optics::Demosaic demosaic = optics::Demosaic::kBilinear;
};

// The outcome of one evaluation, as `lfnet evaluate --json` writes it.
struct EvalResult {
  torch::Tensor estimate;  // (1, U, V, H, W)
  nlohmann::json record;   // psnr_db, ssim, seconds, patches, per_view_psnr_db, ...
};

// Simulates measurements of the grey light field `truth` with `phi`, reconstructs them with
// `solver` and scores the result. `method` names the solver in the record. A non-empty
// `image` solver reconstructs sensor images whole instead (per_patch mode still uses `solver`).
// The truth may be held in 16-bit codes (LightFieldViews): it is then simulated a band at a time
// for a local Phi in sensor mode, and decoded whole otherwise.
EvalResult evaluate(const LightFieldViews& truth, const optics::Phi& phi, const std::string& method,
                    const recon::PatchSolver& solver, const EvalOptions& options,
                    const recon::ProgressCallback& progress = {},
                    const recon::ImageSolver& image = {});

// The no-parallax baseline: every view set to the angular mean of the truth.
EvalResult evaluate_no_parallax(const LightField& truth, const optics::Phi& phi,
                                const EvalOptions& options);

// The PSNR of each of `frames` sub-frames, from a record's per_view_psnr_db of a stacked
// sequence ((T U) x V, docs/video.md): the views' mean squared errors averaged per frame.
// Null (a perfect view) counts as no error; an all-perfect frame is null.
nlohmann::json per_frame_psnr(const nlohmann::json& per_view_psnr_db, int64_t frames);

// The metric fields of a record: psnr_db, ssim, per_view_psnr_db (U x V).
nlohmann::json score(const LightFieldViews& estimate, const LightFieldViews& truth);

}  // namespace lfnet::eval
