// lfnet info: what a light-field folder holds.
#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <chrono>
#include <cstdio>

#include "command.h"
#include "flags.h"
#include "lfnet/core/parallax.h"
#include "lfnet/io/light_field_io.h"

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
    const auto orientation = AngularOrientation::parse(*orient, "--orient");
    const auto layout = io::scan_folder(*dir, *layout_text);
    const auto start = std::chrono::steady_clock::now();
    const LightField lf = reorient(io::read_light_field(*dir, 0, *layout_text), orientation);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const auto& d = lf.data();
    std::printf("folder:    %s\n", dir->c_str());
    std::printf("scheme:    %s\n", io::to_string(layout.scheme).c_str());
    std::printf("grid:      %lld x %lld views (U x V)\n", static_cast<long long>(lf.rows()),
                static_cast<long long>(lf.cols()));
    std::printf("view size: %lld x %lld (W x H), %lld channel(s)\n",
                static_cast<long long>(lf.width()), static_cast<long long>(lf.height()),
                static_cast<long long>(lf.channels()));
    std::printf("shape:     %s (C x U x V x H x W)\n", lf.shape_string().c_str());
    std::printf("values:    min %.4f, max %.4f, mean %.4f\n", d.min().item<double>(),
                d.max().item<double>(), d.mean().item<double>());
    std::printf("loaded in: %.3f s\n", seconds);
    if (!orientation.identity()) std::printf("oriented:  %s\n", orientation.to_string().c_str());
    const auto parallax = check_parallax(lf);
    std::printf("parallax:  %s\n", parallax.summary().c_str());
    if (parallax.verdict == ParallaxVerdict::kDisagree) {
      spdlog::warn(
          "{}: one angular axis looks reversed; load it with --orient flip-u "
          "(docs/conventions.md)",
          *dir);
    }
  });
}

}  // namespace lfnet::app
