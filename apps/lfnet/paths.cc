#include "paths.h"

#include <cerrno>
#include <filesystem>
#include <system_error>

#include "lfnet/core/error.h"
#include "lfnet/core/file_kind.h"

namespace lfnet::app {

namespace fs = std::filesystem;

namespace {

bool starts_with(const std::string& text, const std::string& prefix) {
  return text.rfind(prefix, 0) == 0;
}

// The path type of an option: its type name up to the validators' descriptions ("PATH:FILE").
std::string path_type(const CLI::Option& option) {
  const std::string type = option.get_type_name();
  for (const char* kind : {kInputPath, kRunFolder, kOutputFolder, kOutputFile}) {
    if (type == kind || starts_with(type, std::string(kind) + ":")) return kind;
  }
  return "";
}

CLI::App* find_subcommand(CLI::App* cmd, const std::string& name) {
  for (auto* sub : cmd->get_subcommands([](CLI::App*) { return true; })) {
    if (sub->check_name(name)) return sub;
  }
  return nullptr;
}

// The option `name` of `cmd` or of a command above it (lfnet's own options follow any command).
CLI::Option* find_option(CLI::App* cmd, const std::string& name) {
  for (auto* app = cmd; app != nullptr; app = app->get_parent()) {
    if (auto* option = app->get_option_no_throw(name)) return option;
  }
  return nullptr;
}

bool takes_several(const CLI::Option& option) { return option.get_items_expected_max() > 1; }

// The parts of an input value that name files: the value itself when it exists, else its
// comma-separated parts (--sensor r.tif,g.tif,b.tif); none for inline JSON.
std::vector<std::string> input_parts(const std::string& value) {
  if (value.empty() || value[0] == '{' || value[0] == '[') return {};
  std::error_code ec;
  if (fs::exists(fs::symlink_status(value, ec)) || value.find(',') == std::string::npos) {
    return {value};
  }
  std::vector<std::string> parts;
  size_t begin = 0;
  while (begin <= value.size()) {
    const size_t end = std::min(value.find(',', begin), value.size());
    if (end > begin) parts.push_back(value.substr(begin, end - begin));
    begin = end + 1;
  }
  return parts;
}

// `inner` is `outer`, or lies inside the folder `outer` (both existing).
bool same_or_inside(const fs::path& inner, const fs::path& outer) {
  std::error_code ec;
  if (fs::equivalent(inner, outer, ec)) return true;
  if (!fs::is_directory(outer, ec)) return false;
  const auto a = fs::canonical(inner, ec);
  if (ec) return false;
  const auto b = fs::canonical(outer, ec);
  if (ec) return false;
  auto it = a.begin();
  for (const auto& part : b) {
    if (it == a.end() || *it != part) return false;
    ++it;
  }
  return true;
}

}  // namespace

std::vector<PathFlag> path_flags(CLI::App& app, const std::vector<std::string>& args) {
  std::vector<PathFlag> flags;
  CLI::App* cmd = &app;
  size_t positional = 0;  // the next positional of `cmd` a bare word goes to
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& arg = args[i];
    if (arg == "--") break;
    if (arg.size() > 1 && arg[0] == '-') {
      const auto eq = starts_with(arg, "--") ? arg.find('=') : std::string::npos;
      auto* option = find_option(cmd, arg.substr(0, eq));
      if (option == nullptr || option->get_type_size() == 0) continue;  // unknown, or a flag
      const std::string type = path_type(*option);
      const auto add = [&](const std::string& value) {
        if (!type.empty()) flags.push_back({option->get_name(), value, type});
      };
      if (eq != std::string::npos) {
        add(arg.substr(eq + 1));
        continue;
      }
      // Its values: the next word, or every word up to the next option for a list.
      do {
        if (i + 1 >= args.size() ||
            (!args[i + 1].empty() && args[i + 1][0] == '-' && args[i + 1] != "-")) {
          break;
        }
        add(args[++i]);
      } while (takes_several(*option));
      continue;
    }
    if (auto* sub = find_subcommand(cmd, arg)) {
      cmd = sub;
      positional = 0;
      continue;
    }
    const auto positionals =
        cmd->get_options([](const CLI::Option* o) { return !o->nonpositional(); });
    if (positional < positionals.size()) {
      const auto* option = positionals[positional];
      const std::string type = path_type(*option);
      if (!type.empty()) flags.push_back({option->get_name(), arg, type});
      if (!takes_several(*option)) ++positional;
    }
  }
  return flags;
}

void check_path_flags(const std::vector<PathFlag>& flags) {
  std::vector<std::pair<const PathFlag*, std::string>> inputs;  // each existing input part
  for (const auto& f : flags) {
    const bool run = f.type == kRunFolder;
    if (f.type != kInputPath && !run) continue;
    for (const auto& part : input_parts(f.value)) {
      std::error_code ec;
      const auto status = fs::status(part, ec);
      LFNET_CHECK_AS(ConfigError, !(ec && ec.value() == ELOOP), f.flag, " ", part,
                     " is a link that loops");
      if (fs::exists(status)) {
        const char* kind = special_file_kind(status);
        LFNET_CHECK_AS(ConfigError, kind == nullptr, f.flag, " ", part,
                       " is not a regular file or folder: it is ", kind,
                       ", which lfnet does not read");
        if (!run) inputs.emplace_back(&f, part);
      } else {
        LFNET_CHECK_AS(ConfigError, part.find('/') == std::string::npos, f.flag, " ", part,
                       ": no such file or folder");
      }
    }
  }
  for (const auto& f : flags) {
    if (f.type == kInputPath || f.type == kRunFolder || (f.type == kOutputFile && f.value == "-")) {
      continue;
    }
    std::error_code ec;
    if (!fs::exists(f.value, ec)) continue;
    for (const auto& [input, part] : inputs) {
      // The words of the output policy's own check (core/output.h, check_output_apart).
      LFNET_CHECK_AS(ConfigError, !same_or_inside(part, f.value), f.flag, " ", f.value,
                     fs::equivalent(part, f.value, ec) ? " is the input " : " contains the input ",
                     input->flag, " ", part,
                     ": choose an output apart from what the command reads");
    }
  }
}

}  // namespace lfnet::app
