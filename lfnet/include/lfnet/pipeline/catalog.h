// What the command line lists and parses: the methods and architectures its help texts name, and
// the option types its flags bind, so that the commands (apps/) reach the library through
// pipeline/ and core/ alone (docs/architecture.md).
#pragma once

#include <string>
#include <vector>

#include "lfnet/nn/network.h"
#include "lfnet/optics/cfa.h"
#include "lfnet/optics/measure.h"
#include "lfnet/recon/fully_convolutional.h"

namespace lfnet::pipeline {

// The option types the flags bind (the requests hold them).
using nn::Precision;
using optics::Demosaic;
using optics::SimulationMode;
using recon::CnnMode;

// Every registered method, comma-separated, for help texts; `reconstruction`: only those that
// reconstruct from measurements (not from the true light field).
std::string method_list(bool reconstruction = false);
// The methods that take options (--method-options).
std::string methods_with_options();
// Every registered network architecture, comma-separated.
std::string architecture_list();
// A ConfigError naming the known architectures when `name` is none of them.
void check_architecture(const std::string& name);
// True when `method` reconstructs with a trained network (--model).
bool needs_network(const std::string& method);
// --precision: float32 or bfloat16; a ConfigError otherwise.
Precision parse_precision(const std::string& text);
// --precision auto: bfloat16 where the device has it natively, measured faster, and every model
// (a noise switch: both members) was verified in it (docs/performance.md), else float32.
Precision choose_precision(const std::vector<std::string>& models, const std::string& device);

}  // namespace lfnet::pipeline
