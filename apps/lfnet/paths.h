// The path flags of every command: each is declared where it is added, by its type name, and
// all of them are checked in one place before the command line is parsed (docs/robustness.md,
// "Outputs"). What a file names in turn (a noise switch's members, a config's $.extends, a
// checkpoint's teacher) is the library's to check (pipeline::model_input_files).
#pragma once

#include <CLI/CLI.hpp>

#include <string>
#include <vector>

namespace lfnet::app {

// What a command reads: a file or folder (or several, comma-separated), where the flag may also
// take a value that is no path (a zoo model's name, NAME[:N], inline JSON).
inline constexpr const char* kInputPath = "PATH";
// A run folder a command continues and writes again (train --resume): checked as an input, but
// it may be an output's folder.
inline constexpr const char* kRunFolder = "RUN";
// What a command writes: a folder, or a file (`-`: standard output).
inline constexpr const char* kOutputFolder = "DIR";
inline constexpr const char* kOutputFile = "FILE";

inline CLI::Option* input_path(CLI::Option* option) { return option->type_name(kInputPath); }
inline CLI::Option* run_folder(CLI::Option* option) { return option->type_name(kRunFolder); }
inline CLI::Option* output_folder(CLI::Option* option) { return option->type_name(kOutputFolder); }
inline CLI::Option* output_file(CLI::Option* option) { return option->type_name(kOutputFile); }

// A path flag as given on the command line.
struct PathFlag {
  std::string flag;   // "--model", or a positional's name
  std::string value;  // as given
  std::string type;   // kInputPath, kRunFolder, kOutputFolder or kOutputFile
};

// The path flags of `args` (the command line without the program's name) for the commands of
// `app`, in order; what follows `--` belongs to another command line (lfnet launch) and is left
// out.
std::vector<PathFlag> path_flags(CLI::App& app, const std::vector<std::string>& args);

// Refuses, with a ConfigError naming the flag, before any file is opened: an input that is a
// named pipe, socket or device (opening one would wait forever or read a stream), a loop of
// symbolic links, or a path (it holds a '/') that does not exist; an output that is an input, or
// a folder that contains one (with --force it would be deleted).
void check_path_flags(const std::vector<PathFlag>& flags);

}  // namespace lfnet::app
