// The built-in reconstruction methods, each a recon::Method, and the one list that registers
// them (method_registry.cc calls it once).
#pragma once

#include <functional>
#include <memory>

#include "lfnet/recon/method_registry.h"

namespace lfnet::recon {

using MethodSink = std::function<void(std::unique_ptr<Method>)>;

// Nominal FLOPs of one patch through a linear method: one (U V h w) x (N h w) product.
double linear_patch_flops(const MethodResources& r);
// pinv's: a local model's per-pixel product (recon::pixel_pinv_solver), N U V h w
// multiply-adds; linear_patch_flops for the others.
double pinv_patch_flops(const MethodResources& r);

// Registers net, ae, cnn, dict, pinv, pinv-nlm, adjoint and no-parallax, in that order.
void register_builtin_methods(const MethodSink& add);

}  // namespace lfnet::recon
