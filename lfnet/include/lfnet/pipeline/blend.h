// `lfnet blend`: weight-space ensembling of a finetuned network with the network it was
// finetuned from (Wortsman et al., "Robust fine-tuning of zero-shot models", CVPR 2022):
// each weight both hold becomes (1 - alpha) base + alpha finetuned (docs/training.md,
// "Blending a finetuned model with its base").
#pragma once

#include <cstdint>
#include <string>

namespace lfnet::pipeline {

struct BlendRequest {
  std::string model;   // the finetuned checkpoint: its camera, network options and config are kept
  std::string base;    // the checkpoint it was finetuned from
  double alpha = 0.5;  // 0: the base's weights, 1: the finetuned model's
  std::string out;     // the checkpoint to write
  bool force = false;  // replace an existing file
  std::string command_line;  // recorded in the new checkpoint
};

struct BlendResult {
  int64_t blended = 0;  // parameters both hold (same name and shape), blended
  int64_t kept = 0;     // the model's own parameters, kept as they are
};

// Writes `out` (atomically): `model` with each trainable parameter that `base` holds under the
// same name and shape replaced by the blend; the model's other parameters (e.g. a colour net's
// input and output layers over a grey base) and its buffers (the camera) are kept, its
// optimizer state dropped. Both must be checkpoints of one architecture sharing at least one
// parameter; alpha must lie in [0, 1]. ConfigError or CheckpointError before anything is
// written otherwise.
BlendResult blend_models(const BlendRequest& request);

}  // namespace lfnet::pipeline
