// The solvers behind the reconstruction methods (docs/methods.md); the methods themselves are
// registered in method_registry.h.
#pragma once

#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "lfnet/dict/dictionary.h"
#include "lfnet/dict/sparse_coding.h"
#include "lfnet/nn/network.h"
#include "lfnet/nn/script.h"
#include "lfnet/optics/phi.h"
#include "lfnet/recon/reconstruct.h"

namespace lfnet::recon {

// True for the registered methods that need a trained network.
bool needs_network(const std::string& method);

// The network (`net`) or one of its branches (`ae`, `cnn`; the branch alone, plus the
// network's residual base if it has one), run in inference mode.
PatchSolver network_solver(nn::LightFieldNet net, const std::string& method);

// The same for an exported network (nn::load_script): its forward_branch, without autograd.
PatchSolver script_solver(const nn::ScriptedNetwork& net, const std::string& method);

// What an iterative solver reports besides its patches: how many it coded and how many did
// not converge (OMP stopped on degenerate input, ADMM hit max_iterations). Such patches are
// still finite (the best estimate so far, or zero), never NaN. Updated by every call.
struct SolverReport {
  std::atomic<int64_t> patches{0};
  std::atomic<int64_t> unconverged{0};
};

// `dict`: sparse coding of y = A D alpha per patch with the dictionary (OMP or ADMM-LASSO, by
// the options), one prepared operator per distinct patch matrix. `report`, when given, counts
// the patches that did not converge.
PatchSolver dictionary_solver(const optics::Phi& phi, const dict::Dictionary& dictionary,
                              const dict::SparseCodingOptions& options, int64_t patch_h,
                              int64_t patch_w, std::shared_ptr<SolverReport> report = nullptr);

}  // namespace lfnet::recon
