// The table of lfnet subcommands. Each subcommand is a thin layer over the library.
#pragma once

#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdint>
#include <functional>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/core/version.h"
#include "lfnet/pipeline/catalog.h"
#include "lfnet/pipeline/zoo.h"
#include "paths.h"

namespace lfnet::app {

using lfnet::kVersion;

// Settings every subcommand shares.
struct GlobalOptions {
  int threads = 0;                 // 0: every core
  std::string log_level = "info";  // trace, debug, info, warn, error, off
};

// Option checks with short messages that name the value: CLI11's own ranges print the
// type's limits (a 309-digit number for a double).
// A Gaussian noise sigma, relative to a white scene's measurement: a finite number from 0 to
// 10 (sigma 10 already buries any signal; larger values would write infinities into sensor
// files). nan, inf, negatives and overflowing numbers are refused with this message.
inline const CLI::Validator kNoiseSigma(
    [](std::string& text) -> std::string {
      double v = 0;
      if (!CLI::detail::lexical_cast(text, v) || !std::isfinite(v) || v < 0 || v > 10) {
        return "must be a noise sigma from 0 to 10 (relative to white), got " + text;
      }
      return "";
    },
    "0..10");
// A value that may not be empty: `--cfa ""` is no grey sensor, it is a mistake.
inline const CLI::Validator kNotEmpty(
    [](std::string& text) -> std::string { return text.empty() ? "may not be empty" : ""; },
    "TEXT");
// A seed: a whole number from 0 to 2^64 - 1, read exactly: -1 does not wrap around and larger
// numbers do not saturate to the same seed.
inline const CLI::Validator kSeed(
    [](std::string& text) -> std::string {
      const std::string message =
          "must be a whole number from 0 to 18446744073709551615 (2^64 - 1), got " + text;
      if (text.empty() || text.size() > 20 ||
          text.find_first_not_of("0123456789") != std::string::npos) {
        return message;
      }
      // 20 digits: compare with 2^64 - 1 as text.
      if (text.size() == 20 && text > "18446744073709551615") return message;
      return "";
    },
    "0..2^64-1");
// A patch stride: a whole number from 1 to 64 (the largest patch side; the patch size itself
// bounds it further when the patch is known).
inline const CLI::Validator kStride(
    [](std::string& text) -> std::string {
      int64_t v = 0;
      if (!CLI::detail::lexical_cast(text, v) || v < 1 || v > 64) {
        return "must be a whole number from 1 to the patch size (9 by default), got " + text;
      }
      return "";
    },
    "1..PATCH");

// A whole number >= `lo`, without an upper bound.
inline CLI::Validator whole_number_at_least(int64_t lo) {
  const std::string bound = ">= " + std::to_string(lo);
  return CLI::Validator(
      [lo, bound](std::string& text) -> std::string {
        int64_t v = 0;
        if (!CLI::detail::lexical_cast(text, v) || v < lo) {
          return "must be a whole number " + bound + ", got " + text;
        }
        return "";
      },
      "N" + bound.substr(0, 2) + std::to_string(lo));
}
// A count: a whole number >= 1.
inline const CLI::Validator kCount = whole_number_at_least(1);
// A whole number >= 0 (an index, a seed of a scene, a count that may be none).
inline const CLI::Validator kWhole = whole_number_at_least(0);

// A whole number of `unit` from `lo` to `hi`.
inline CLI::Validator whole_number_in(int64_t lo, int64_t hi, const std::string& unit) {
  const std::string range = std::to_string(lo) + ".." + std::to_string(hi);
  return CLI::Validator(
      [lo, hi, unit](std::string& text) -> std::string {
        int64_t v = 0;
        if (!CLI::detail::lexical_cast(text, v) || v < lo || v > hi) {
          return "must be a whole number of " + unit + " from " + std::to_string(lo) + " to " +
                 std::to_string(hi) + ", got " + text;
        }
        return "";
      },
      range);
}

// A duration in seconds, at most a year: >= 0, or > 0 for a timeout.
inline CLI::Validator seconds_validator(bool positive) {
  return CLI::Validator(
      [positive](std::string& text) -> std::string {
        double v = 0;
        if (!CLI::detail::lexical_cast(text, v) || !std::isfinite(v) || v < 0 ||
            (positive && v == 0) || v > 3.2e7) {
          return std::string("must be a number of seconds ") + (positive ? "above 0" : "from 0") +
                 " to 3.2e7 (a year), got " + text;
        }
        return "";
      },
      "SECONDS");
}
inline const CLI::Validator kSeconds = seconds_validator(false);
inline const CLI::Validator kTimeout = seconds_validator(true);

// An option whose value names one of an enum's values, read by the enum's `from_string` (its
// one name table, core/enum_names.h): a bad name is a usage error naming the option and the
// known names. Repeatable when `value` is a vector; given values then replace the default.
template <typename E>
E parse_enum_option(const std::string& flag, const std::string& text) {
  try {
    return from_string(text, E{});
  } catch (const ConfigError& e) {
    throw CLI::ValidationError(flag, e.what());
  }
}
template <typename E>
CLI::Option* add_enum_option(CLI::App* cmd, const std::string& flag, E& value,
                             const std::string& help) {
  return cmd->add_option_function<std::string>(
      flag, [&value, flag](const std::string& text) { value = parse_enum_option<E>(flag, text); },
      help);
}
// --demosaic of evaluate, reconstruct and batch.
inline CLI::Option* add_demosaic_option(CLI::App* cmd, pipeline::Demosaic& value) {
  return add_enum_option(cmd, "--demosaic", value,
                         "behind a colour filter array, how the views of pinv and adjoint are "
                         "demosaiced: bilinear (default) or malvar, gradient-corrected "
                         "(docs/acquisition.md); colour nets demosaic inside themselves");
}
template <typename E>
CLI::Option* add_enum_option(CLI::App* cmd, const std::string& flag, std::vector<E>& values,
                             const std::string& help) {
  return cmd->add_option_function<std::vector<std::string>>(
      flag,
      [&values, flag](const std::vector<std::string>& texts) {
        values.clear();
        for (const auto& text : texts) values.push_back(parse_enum_option<E>(flag, text));
      },
      help);
}

// --self-ensemble and --ensemble-passes: lfnet models averaged over the Phi's mirror images
// (recon::reconstruct_sensor_mirrored), all of them or the first `passes`.
inline void add_self_ensemble_options(CLI::App* cmd, bool& self_ensemble, int64_t& passes) {
  auto* flag = cmd->add_flag(
      "--self-ensemble", self_ensemble,
      "whole-image models: reconstruct the sensor image's mirror images that the Phi allows too "
      "(asp:2 all four) and average, at that many times the cost (docs/architectures.md)");
  cmd->add_option("--ensemble-passes", passes,
                  "with --self-ensemble: the first N of those passes only, the identity first, "
                  "then left to right, top to bottom, both (default: all)")
      ->check(kCount)
      ->needs(flag);
}

// --self-calibrate: lfnet models estimate the camera's angular shift from each sensor image and
// are told the Phi so displaced (recon/self_calibration.h).
inline void add_self_calibrate_flag(CLI::App* cmd, bool& self_calibrate) {
  cmd->add_flag("--self-calibrate", self_calibrate,
                "lfnet models: estimate the camera's angular shift (a response displaced "
                "against the nominal Phi) from each sensor image and reconstruct with the Phi so "
                "displaced (docs/acquisition.md, \"Self-calibration\")");
}

// The transform of every flag that takes a model file: a zoo model's name stands for its file
// (pipeline/zoo.h, `lfnet models`).
inline std::string zoo_model_file(std::string text) { return pipeline::resolve_model_name(text); }

// Adds one subcommand to `app`. The subcommand's callback does the work and throws on error.
using CommandFactory = std::function<void(CLI::App& app, const GlobalOptions& global)>;

void add_info_command(CLI::App& app, const GlobalOptions& global);
void add_simulate_command(CLI::App& app, const GlobalOptions& global);
void add_render_command(CLI::App& app, const GlobalOptions& global);
void add_train_command(CLI::App& app, const GlobalOptions& global);
void add_experiment_command(CLI::App& app, const GlobalOptions& global);
void add_evaluate_command(CLI::App& app, const GlobalOptions& global);
void add_reconstruct_command(CLI::App& app, const GlobalOptions& global);
void add_batch_command(CLI::App& app, const GlobalOptions& global);
void add_report_command(CLI::App& app, const GlobalOptions& global);
void add_export_command(CLI::App& app, const GlobalOptions& global);
void add_launch_command(CLI::App& app, const GlobalOptions& global);
void add_bench_command(CLI::App& app, const GlobalOptions& global);
void add_phi_command(CLI::App& app, const GlobalOptions& global);
void add_blend_command(CLI::App& app, const GlobalOptions& global);
void add_sets_command(CLI::App& app, const GlobalOptions& global);
void add_models_command(CLI::App& app, const GlobalOptions& global);

}  // namespace lfnet::app
