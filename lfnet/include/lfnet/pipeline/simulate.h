// Coded capture into an acquisition folder: what `lfnet simulate` writes and `lfnet
// reconstruct` reads (docs/acquisition.md, "The acquisition folder").
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>

#include "lfnet/core/light_field.h"
#include "lfnet/optics/measure.h"
#include "lfnet/optics/phi.h"
#include "lfnet/optics/sensor.h"

namespace lfnet::pipeline {

// One simulation: a light field coded by a Phi, with sensor effects.
struct SimulateRequest {
  LightField lf;  // (C, U, V, H, W): the window the Phi codes, grey or colour
  const optics::Phi* phi = nullptr;
  optics::SensorOptions effects;  // noise and the rest (validated by the caller)
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

}  // namespace lfnet::pipeline
