// Times every Phi model on a light field of the paper's dragons size (593 x 840 x 5 x 5):
// forward, adjoint, forward with Gaussian noise, and per-patch measurements at stride 5.
// Usage: optics_bench [N] [threads] [repeats]. Best of `repeats` after one warm-up call.
#include <torch/torch.h>

#include <cstdio>
#include <cstdlib>

#include "lfnet/core/patches.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/optics/measure.h"

int main(int argc, char** argv) {
  const int64_t n = argc > 1 ? std::atoll(argv[1]) : 2;
  const int threads = lfnet::configure_threads(argc > 2 ? std::atoi(argv[2]) : 0);
  const int repeats = argc > 3 ? std::atoi(argv[3]) : 5;
  const int64_t h = 593, w = 840;
  torch::manual_seed(0);
  auto lf = torch::rand({1, 5, 5, h, w});
  lfnet::optics::SensorOptions noise;
  noise.gaussian = lfnet::optics::SensorOptions::Gaussian{0.1};
  const lfnet::PatchGrid grid(h, w, 9, 9, 5);
  std::printf("light field 1x5x5x%lldx%lld, N = %lld, %d threads, best of %d (seconds)\n",
              static_cast<long long>(h), static_cast<long long>(w), static_cast<long long>(n),
              threads, repeats);
  std::printf("%-9s %8s %8s %8s %10s %14s\n", "model", "build", "forward", "adjoint", "fwd+noise",
              "per_patch s=5");
  for (const char* name : {"asp", "mask", "aperture", "random", "lenslet"}) {
    auto spec = lfnet::optics::PhiSpec::parse(std::string(name) + ":" + std::to_string(n));
    lfnet::Stopwatch clock;
    auto phi = lfnet::optics::make_phi(spec);
    const double build = clock.seconds();
    auto y = phi->forward(lf);
    double best[4] = {1e30, 1e30, 1e30, 1e30};
    for (int r = 0; r < repeats; ++r) {
      clock.reset();
      y = phi->forward(lf);
      best[0] = std::min(best[0], clock.seconds());
      clock.reset();
      auto x = phi->adjoint(y);
      best[1] = std::min(best[1], clock.seconds());
      clock.reset();
      auto noisy = lfnet::optics::simulate_sensor(*phi, lf, noise, 1);
      best[2] = std::min(best[2], clock.seconds());
      clock.reset();
      auto m =
          lfnet::optics::measure_patches(*phi, lf, grid, lfnet::optics::SimulationMode::kPerPatch);
      best[3] = std::min(best[3], clock.seconds());
    }
    std::printf("%-9s %8.3f %8.3f %8.3f %10.3f %14.3f\n", name, build, best[0], best[1], best[2],
                best[3]);
  }
  std::printf("per_patch: %lld patches of 9 x 9 at stride 5\n",
              static_cast<long long>(grid.size()));
  return 0;
}
