// A time budget (docs/models.md, "A time budget"): `--budget SECONDS` of reconstruct, evaluate
// and batch runs the most accurate zoo model for the camera whose reconstruction this machine
// finishes within SECONDS, as predicted from a per-machine calibration that `lfnet bench
// --calibrate` writes (and that a budget completes by itself when the machine changes or a
// model is missing from it).
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "lfnet/nn/network.h"
#include "lfnet/pipeline/zoo.h"

namespace lfnet::pipeline {

// Where this machine's calibration is kept: $LFNET_CALIBRATION, else
// $XDG_CACHE_HOME/lfnet/calibration.json, else ~/.cache/lfnet/calibration.json.
std::string calibration_path();

// What a calibration holds for: the CPU's model name, its logical cores, and the lfnet and
// LibTorch versions. A calibration of another fingerprint is stale and is not used.
nlohmann::json machine_fingerprint();

// How a run is timed: its device, threads and precision (an entry holds for these only).
struct TimingSetting {
  std::string device = "cpu";
  int threads = 1;
  nn::Precision precision = nn::Precision::kFloat32;
  nlohmann::json to_json() const;
};

// The setting `model` runs in here: `device`, LibTorch's thread count, and `precision`, or when
// that is nullopt (--precision auto) the precision auto chooses for the model (float32 for pinv,
// `model` "").
TimingSetting run_setting(const std::string& model, const std::string& device,
                          std::optional<nn::Precision> precision);

// One timing in a calibration: a zoo model (or "pinv" for a camera and colour) reconstructing
// whole sensor images of two sizes, and the line through them, seconds = fixed + per_pixel *
// light-field pixels (height x width).
struct CalibrationEntry {
  std::string model;  // a zoo card's name, or "pinv"
  std::string camera, colour;
  int64_t file_bytes = 0;  // the model file's size when it was timed (0: pinv)
  TimingSetting setting;
  double fixed = 0, per_pixel = 0;
  std::vector<std::pair<int64_t, double>> timings;  // (pixels, seconds) as measured
  // The line through `timings` (least squares); where the timings are noisier than the size's
  // effect (a negative slope or intercept), the largest timing alone, proportional to pixels.
  void fit();
  double predict(int64_t pixels) const { return fixed + per_pixel * static_cast<double>(pixels); }
  nlohmann::json to_json() const;
  static CalibrationEntry from_json(const nlohmann::json& j);
};

// A machine's calibration: its fingerprint and its entries.
struct Calibration {
  nlohmann::json machine;
  std::vector<CalibrationEntry> entries;
  const CalibrationEntry* find(const std::string& model, const std::string& camera,
                               const std::string& colour, const TimingSetting& setting) const;
  void put(const CalibrationEntry& entry);  // replaces the entry of the same key
};

// The calibration at `path` if it is this machine's; empty (with this machine's fingerprint)
// when the file is missing, of another machine (said once in the log) or unreadable.
Calibration read_calibration(const std::string& path);
void write_calibration(const std::string& path, const Calibration& calibration);

// What `lfnet bench --calibrate` times.
struct CalibrateOptions {
  std::vector<std::string> models;  // zoo names; empty: every model a budget can choose
  std::string device = "cpu";
  std::optional<nn::Precision> precision;  // nullopt: auto, per model
  int64_t height = 593, width = 840;       // the larger size; the smaller is half of each side
  uint64_t seed = 7;                       // of the random scene timed
  std::string path;                        // the calibration file ("": calibration_path())
};

// Times the models (and pinv once per camera and colour among them) on this machine, each on a
// random scene of its camera and colour at two sizes, after one untimed warm-up; adds them to
// the calibration file and returns the entries timed. `print` gets a line per entry.
std::vector<CalibrationEntry> calibrate_machine(
    const CalibrateOptions& options, const std::function<void(const std::string&)>& print);

// The zoo models a budget chooses among for a camera and colour: the cards of that camera and
// colour whose file is a network, with how accurate each is. `accuracy` is the card's mean
// margin over pinv on the validation set (docs/protocol.md), or, where no card of the camera
// has validation figures, on its benchmark section; a card without the figure the others have
// is left out.
struct BudgetCandidate {
  std::string name, path;
  double accuracy = 0;
  std::string basis;  // "validation" or the benchmark section
};
std::vector<BudgetCandidate> budget_candidates(const Zoo& zoo, const std::string& camera,
                                               const std::string& colour);

// The ladder of a camera: the checkpoints among its grey candidates, most accurate first (a
// noise switch is left out: its quiet member is a checkpoint of the zoo). `lfnet bench --ladder`
// times them in one run.
std::vector<std::string> ladder_models(const std::string& camera);

// The choice a budget made; `record()` is what reconstruction records hold as "budget".
struct BudgetChoice {
  double budget = 0;
  std::string model, path;  // the zoo card's name and file
  double predicted_seconds = 0;
  std::string camera, colour;
  int64_t pixels = 0;
  TimingSetting setting;                                // what the choice runs in
  nlohmann::json candidates = nlohmann::json::array();  // name, accuracy, predicted seconds
  nlohmann::json record() const;
  std::string summary() const;  // one line for the log
};

// The most accurate candidate for `camera` and `colour` whose predicted seconds for a light
// field of `pixels` (height x width) fit `budget` on `device` in `precision` (nullopt: auto).
// Entries the calibration lacks are timed first and written to it (logged). A camera without
// candidates, and a budget none fits, are ConfigErrors (the latter naming the fastest model's
// seconds and pinv's).
BudgetChoice choose_within_budget(double budget, const std::string& camera,
                                  const std::string& colour, int64_t pixels,
                                  const std::string& device,
                                  std::optional<nn::Precision> precision);

// What a budget is refused with, as ConfigErrors naming the flag: a model or method of one's own
// (the budget chooses them), and the self-ensemble, self-calibration and per-patch measurements
// (which its timings do not include).
struct BudgetConflicts {
  bool model = false, method = false, self_ensemble = false, self_calibrate = false,
       per_patch = false;
};
void check_budget_request(const BudgetConflicts& given);

// The choice for a sensor image (sensor_facts) or for a light field evaluated through `phi`
// and `cfa` (`pixels` of its views), logged.
BudgetChoice budget_for_sensor(double budget, const std::string& sensor, const std::string& phi,
                               const std::string& cfa, const std::string& device,
                               std::optional<nn::Precision> precision);
BudgetChoice budget_for_light_field(double budget, int64_t pixels, const std::string& phi,
                                    const std::string& cfa, const std::string& device,
                                    std::optional<nn::Precision> precision);

// Adds the choice to a reconstruction's record as "budget" and logs predicted against actual.
void record_budget(const BudgetChoice& choice, nlohmann::json& record);

// The camera, colour and light-field size of a sensor image: an acquisition folder, or a
// camera's own sensor image files with `phi` (and `cfa`), as `lfnet reconstruct` takes them.
struct SensorFacts {
  std::string camera, colour;
  int64_t height = 0, width = 0;
};
SensorFacts sensor_facts(const std::string& sensor, const std::string& phi, const std::string& cfa);

// The pixels (height x width) of a light field's views: a folder (read in `layout`, one view
// read) or a scene spec (its size), whichever is given.
int64_t light_field_pixels(const std::string& lf, const std::string& layout,
                           const std::string& scene);

}  // namespace lfnet::pipeline
