// adjoint: A^T y, the simplest linear estimate (a sanity baseline).
#include "lfnet/optics/measure.h"
#include "lfnet/recon/builtin_methods.h"

namespace lfnet::recon {

namespace {

class AdjointMethod : public Method {
 public:
  std::string name() const override { return "adjoint"; }
  std::string summary() const override { return "the adjoint A^T y (linear, a sanity baseline)"; }
  bool baseline() const override { return true; }
  PatchSolver solver(const MethodResources& r) const override {
    return adjoint_solver(optics::patch_matrix_stack(*r.phi, r.patch_h, r.patch_w));
  }
  double patch_flops(const MethodResources& r) const override { return linear_patch_flops(r); }
};

}  // namespace

// Declared and registered in builtin_methods.cc.
std::unique_ptr<Method> make_adjoint_method() { return std::make_unique<AdjointMethod>(); }

}  // namespace lfnet::recon
