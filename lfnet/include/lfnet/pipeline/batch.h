// Batches: reconstruct every acquisition folder, or evaluate every light-field folder, under a
// directory (`lfnet batch`). One JSON record per item and method, a summary CSV and JSON; a bad
// item is recorded with its error and the others go on.
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "lfnet/dist/communicator.h"
#include "lfnet/optics/measure.h"
#include "lfnet/pipeline/models.h"

namespace lfnet::pipeline {

// What a batch does with every item.
struct BatchOptions {
  std::string in;   // folder searched recursively for items
  std::string out;  // output folder: reconstructions, records/, summary.*
  std::vector<std::string>
      methods;                 // methods run on every item (empty: net with a model, else pinv)
  std::string model;           // checkpoint or exported model for net, ae, cnn
  std::string dictionary;      // dictionary file for dict
  std::string method_options;  // --method-options: JSON or file, keyed by method
  std::string phi;             // Phi of evaluations without a model; must match the model
  std::string device = "cpu";  // cpu or cuda[:K] for the network
  nn::Precision precision = nn::Precision::kFloat32;  // of the CNN branch (lfnet: the U-Net)
  int64_t tile = 0;  // whole-image methods' spatial tile (0: their default, 256)
  optics::SimulationMode mode = optics::SimulationMode::kSensor;  // of evaluations
  int64_t stride = 5;                                             // patch stride
  int64_t batch = 1024;                                           // patches per solver call
  double noise = 0;  // Gaussian noise sigma of evaluations
  std::string cfa;   // evaluations behind a colour filter array (a Bayer pattern or a JSON file)
  optics::Demosaic demosaic = optics::Demosaic::kBilinear;  // of pinv's views behind one
  uint64_t seed = 0;                                        // noise seed of evaluations
  bool window = false;       // weight patch estimates by a smooth window when stitching
  bool post_filter = false;  // suppress artefacts with the stride's period
  bool match_mean = false;   // scale real measurements to the training mean
  std::string flat_field;    // the camera's white frame, divided out of every acquisition; "" none
  bool self_ensemble = false;        // net with an lfnet checkpoint: average over the Phi's mirrors
  int64_t self_ensemble_passes = 0;  // at most this many of them (0: all)
  bool self_calibrate = false;       // net with an lfnet checkpoint: estimate the angular shift
  // --budget SECONDS: each item runs the most accurate zoo model for its camera that fits
  // (pipeline/budget.h) instead of `model`; 0: none. `budget_precision` is --precision as
  // given (nullopt: auto, per model).
  double budget = 0;
  std::optional<nn::Precision> budget_precision;
  bool force = false;  // write into an existing non-empty output folder
  // Continue the batch in `out`: the item-method pairs with a record of status "ok" are kept,
  // the others (failed, or never finished) are done. The batch's options must be the same.
  bool resume = false;
};

// One thing to process: an acquisition folder (reconstruct) or a light-field folder (evaluate).
struct BatchItem {
  std::string path;  // the folder
  std::string name;  // its path relative to the batch's input, '/' separated
  std::string kind;  // "reconstruct", "evaluate", or "unreadable" (with `error`)
  std::string error;
};

// Every acquisition and light-field folder under `root` (the root itself included), sorted by
// name; a folder that is an item is not searched further. Folders that cannot be read, broken
// links and links back to a folder already visited are items of kind "unreadable".
std::vector<BatchItem> discover_items(const std::string& root);

// The records of one item, one per method; errors become records with status "error". An
// acquisition's reconstructions are written under `out_dir`/<item name>/<method>.
std::vector<nlohmann::json> process_item(const BatchItem& item, const BatchOptions& options,
                                         const std::vector<std::string>& methods,
                                         const std::string& out_dir, ModelCache& cache);

// What a batch did (on rank 0 every rank's records, in item order).
struct BatchSummary {
  std::vector<nlohmann::json> records;
  int64_t failures = 0;
  int64_t loads = 0;  // model or dictionary files read
};

// Runs a batch into options.out (the output-folder policy of core/output.h). With a
// communicator of several ranks, rank r takes items r, r + W, ... of the pairs still to do;
// rank 0 writes the summary. Failed items do not throw: they are counted in the summary. With
// options.resume, what OUT/records holds already is kept and not done again.
BatchSummary run_batch(const BatchOptions& options,
                       std::shared_ptr<dist::Communicator> comm = nullptr);

// What decides a batch's results, as recorded in OUT/batch.json; `--resume` must match it.
nlohmann::json batch_manifest(const BatchOptions& options, const std::vector<std::string>& methods);

// The summary files of a batch: OUT/summary.csv (one row per record) and OUT/summary.json.
void write_batch_summary(const std::string& out_dir, const std::vector<nlohmann::json>& records);

}  // namespace lfnet::pipeline
