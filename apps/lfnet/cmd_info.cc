// lfnet info: what a light-field folder holds.
#include <spdlog/spdlog.h>

#include <cstdio>

#include "command.h"
#include "flags.h"
#include "lfnet/pipeline/sources.h"

namespace lfnet::app {

void add_info_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand(
      "info", "Print the shape, value range, naming scheme and grid of a light field folder");
  auto dir = std::make_shared<std::string>();
  auto orient = std::make_shared<std::string>();
  auto layout_text = std::make_shared<std::string>();
  add_lf_option(cmd, *dir)->required();
  add_orient_option(cmd, *orient);
  add_layout_option(cmd, *layout_text);
  cmd->callback([dir, orient, layout_text] {
    const auto info = pipeline::describe_light_field_folder(*dir, *orient, *layout_text);
    std::fputs(info.text.c_str(), stdout);
    if (info.axis_reversed) {
      spdlog::warn(
          "{}: one angular axis looks reversed; load it with --orient flip-u "
          "(docs/conventions.md)",
          *dir);
    }
  });
}

}  // namespace lfnet::app
