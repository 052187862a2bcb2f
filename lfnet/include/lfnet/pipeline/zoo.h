// The model zoo (docs/models.md): models/zoo.json holds one card per shipped model, and a card's
// name stands for its file wherever a model is taken (`--model lfnet-asp-n2`).
#pragma once

#include <nlohmann/json.hpp>

#include <optional>
#include <string>
#include <vector>

namespace lfnet::pipeline {

struct ZooCard {
  std::string name, file;  // file: relative to the zoo's folder
  nlohmann::json card;     // the whole card as zoo.json holds it
};

struct Zoo {
  std::string dir;  // the folder of zoo.json and the models
  std::vector<ZooCard> models;
  const ZooCard* find(const std::string& name) const;
  std::string path(const ZooCard& card) const;  // the card's file in the zoo's folder
  // The card marked `default` for a camera (a Phi spec's label, "asp:2") and colour ("grey", or
  // a colour filter array's pattern, "RGGB"); nullptr when the zoo has none.
  const ZooCard* default_for(const std::string& camera, const std::string& colour) const;
};

// The zoo's folder: $LFNET_MODELS when set, else ./models when it holds zoo.json, else the
// source tree's models/ (where the program was built).
std::string zoo_dir();

// Reads DIR/zoo.json. A missing or malformed file is an IoError or ConfigError naming it.
Zoo read_zoo(const std::string& dir = zoo_dir());

// `text` itself when it names an existing file or folder or the zoo cannot be read; else the
// path of the zoo model it names, if any. Never throws.
std::string resolve_model_name(const std::string& text);

// The camera (a Phi spec's label) and colour (grey, or a colour filter array's pattern) of a
// sensor image: read from `sensor` (an acquisition folder's sensor.json) or from `phi` and `cfa`
// (a plain sensor image's --phi and --cfa, or the colour filter array a calibrated Phi names).
// `camera` is empty when they cannot be read (the reconstruction then says why); never throws.
//
// The zoo's default model for a sensor image: the card marked default for its camera and colour.
// `name` and `path` are empty when the zoo has no default for the camera, and `camera` too when the
// camera cannot be read (the reconstruction then says why).
struct SensorCamera {
  std::string camera, colour = "grey";
};
SensorCamera sensor_camera(const std::string& sensor, const std::string& phi,
                           const std::string& cfa = "");
struct ZooDefault {
  std::string camera, colour, name, path;
};
ZooDefault zoo_default_model(const std::string& sensor, const std::string& phi,
                             const std::string& cfa = "");

// The table `lfnet models` prints: name, camera, colour, noise, architecture, parameters, MB,
// worst margins over pinv on the validation and test sets, use.
std::string zoo_table(const Zoo& zoo);

// One card with what is measured on the file itself (parameters, MB) added, as JSON text.
std::string zoo_card(const Zoo& zoo, const std::string& name);

}  // namespace lfnet::pipeline
