// The table of lfnet subcommands. Each subcommand is a thin layer over the library.
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <string>

namespace lfnet::app {

// The program's version, recorded in every output it writes.
constexpr const char* kVersion = "0.1.0";

// Settings every subcommand shares.
struct GlobalOptions {
  int threads = 0;                 // 0: every core
  std::string log_level = "info";  // trace, debug, info, warn, error, off
};

// Adds one subcommand to `app`. The subcommand's callback does the work and throws on error.
using CommandFactory = std::function<void(CLI::App& app, const GlobalOptions& global)>;

void add_info_command(CLI::App& app, const GlobalOptions& global);
void add_simulate_command(CLI::App& app, const GlobalOptions& global);
void add_render_command(CLI::App& app, const GlobalOptions& global);
void add_train_command(CLI::App& app, const GlobalOptions& global);
void add_experiment_command(CLI::App& app, const GlobalOptions& global);
void add_evaluate_command(CLI::App& app, const GlobalOptions& global);

}  // namespace lfnet::app
