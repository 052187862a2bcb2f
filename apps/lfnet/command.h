// The table of lfnet subcommands. Each subcommand is a thin layer over the library.
#pragma once

#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/core/version.h"

namespace lfnet::app {

using lfnet::kVersion;

// Settings every subcommand shares.
struct GlobalOptions {
  int threads = 0;                 // 0: every core
  std::string log_level = "info";  // trace, debug, info, warn, error, off
};

// Option checks with short messages that name the value: CLI11's own ranges print the
// type's limits (a 309-digit number for a double).
// A finite number >= 0 (noise sigmas): nan, inf and negatives are refused.
inline const CLI::Validator kFiniteNonNegative(
    [](std::string& text) -> std::string {
      double v = 0;
      if (!CLI::detail::lexical_cast(text, v) || !std::isfinite(v) || v < 0) {
        return "must be a finite number >= 0, got " + text;
      }
      return "";
    },
    "FLOAT>=0");
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

// A count: a whole number >= 1.
inline const CLI::Validator kCount(
    [](std::string& text) -> std::string {
      int64_t v = 0;
      if (!CLI::detail::lexical_cast(text, v) || v < 1) {
        return "must be a whole number >= 1, got " + text;
      }
      return "";
    },
    "N>=1");

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

// --dict-method and --dict-options: how the dict method codes (pipeline::dict_coding).
inline void add_dict_coding_options(CLI::App* cmd, std::string& method, std::string& options) {
  cmd->add_option("--dict-method", method,
                  "sparse coding for dict: omp or admm (default: the dictionary's)")
      ->check(CLI::IsMember({"omp", "admm"}));
  cmd->add_option("--dict-options", options,
                  "sparse coding for dict: a JSON object or file, e.g. '{\"omp\": "
                  "{\"max_atoms\": 20}}' (docs/dictionary.md)");
}

// --self-ensemble and --ensemble-passes: lfnet models averaged over the Phi's mirror images
// (recon::reconstruct_sensor_mirrored), all of them or the first `passes`. `what` opens the
// flag's help ("reconstruct" or "time").
inline void add_self_ensemble_options(CLI::App* cmd, bool& self_ensemble, int64_t& passes,
                                      const std::string& what = "reconstruct") {
  auto* flag = cmd->add_flag(
      "--self-ensemble", self_ensemble,
      "lfnet models: " + what +
          " the sensor image's mirror images that the Phi allows too (asp:2 all four) and "
          "average, at that many times the cost (docs/architectures.md)");
  cmd->add_option("--ensemble-passes", passes,
                  "with --self-ensemble: the first N of those passes only, the identity first, "
                  "then left to right, top to bottom, both (default: all)")
      ->check(kCount)
      ->needs(flag);
}

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

}  // namespace lfnet::app
