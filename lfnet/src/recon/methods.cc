#include "lfnet/recon/methods.h"

#include <torch/torch.h>

#include <algorithm>

#include "lfnet/core/error.h"
#include "lfnet/optics/measure.h"

namespace lfnet::recon {

PatchSolver network_solver(nn::LightFieldNet net, const std::string& method) {
  LFNET_CHECK_AS(ConfigError, needs_network(method), "method '", method,
                 "' is not a network method (net, ae, cnn)");
  const auto& o = net->options();
  const auto branches = nn::to_string(o.branches());
  const bool two_branch = o.branches() == nn::Branches::kNet;
  LFNET_CHECK_AS(ConfigError, method == "net" || branches == "net" || branches == method,
                 "the model was trained as '", branches, "' and has no '", method, "' branch");
  net->eval();
  // The `ae` and `cnn` methods run their branch alone. Measurements go to the net's device
  // and patches come back to the CPU, where they are stitched.
  nn::BranchSelection run;
  run.ae = method != "cnn";
  run.cnn = method != "ae";
  return
      [net, method, run, two_branch](const torch::Tensor& y, const torch::Tensor& phase) mutable {
        torch::InferenceMode guard;
        const auto device = net->phi.device();
        auto out = net->forward_all(y.to(device), phase.defined() ? phase.to(device) : phase, run);
        torch::Tensor patch = out.output;
        if (method == "ae" && two_branch) {
          patch = out.base.defined() ? out.ae + out.base : out.ae;
        } else if (method == "cnn" && two_branch) {
          patch = out.base.defined() ? out.cnn + out.base : out.cnn;
        }
        return patch.reshape({y.size(0), -1}).to(torch::kCPU);
      };
}

PatchSolver script_solver(const nn::ScriptedNetwork& net, const std::string& method) {
  LFNET_CHECK_AS(ConfigError, needs_network(method), "method '", method,
                 "' is not a network method (net, ae, cnn)");
  const auto branches = nn::to_string(net.network.branches());
  LFNET_CHECK_AS(ConfigError, method == "net" || branches == "net" || branches == method,
                 "the model was trained as '", branches, "' and has no '", method, "' branch");
  return [net, method](const torch::Tensor& y, const torch::Tensor& phase) {
    return net.forward(y, phase, method).reshape({y.size(0), -1});
  };
}

PatchSolver dictionary_solver(const optics::Phi& phi, const dict::Dictionary& dictionary,
                              const dict::SparseCodingOptions& options, int64_t patch_h,
                              int64_t patch_w, std::shared_ptr<SolverReport> report) {
  dictionary.validate();
  const std::array<int64_t, 4> shape{phi.rows(), phi.cols(), patch_h, patch_w};
  LFNET_CHECK_AS(ConfigError, dictionary.patch_shape == shape, "the dictionary's atoms are ",
                 dictionary.patch_shape[0], "x", dictionary.patch_shape[1], "x",
                 dictionary.patch_shape[2], "x", dictionary.patch_shape[3],
                 " patches, but the reconstruction uses ", phi.rows(), "x", phi.cols(), "x",
                 patch_h, "x", patch_w);
  auto matrices = optics::patch_matrix_stack(phi, patch_h, patch_w);
  auto coder = std::make_shared<dict::SparseCoder>(dictionary.atoms, options);
  return [matrices, coder, report](const torch::Tensor& y, const torch::Tensor& phase) {
    return by_phase(y, phase, matrices.size(2), [&](const torch::Tensor& rows, int64_t p) {
      auto result = coder->code(matrices[p], rows);
      if (report) {
        report->patches += rows.size(0);
        report->unconverged += result.unconverged();
      }
      return result.patches.to(torch::kFloat32);
    });
  };
}

}  // namespace lfnet::recon
