// The built-in reconstruction methods, each a recon::Method, and the one list that registers
// them (method_registry.cc calls it once).
#pragma once

#include <functional>
#include <memory>

#include "lfnet/recon/method_registry.h"

namespace lfnet::recon {

using MethodSink = std::function<void(std::unique_ptr<Method>)>;

// Registers net, ae, cnn, dict, pinv, adjoint and no-parallax, in that order.
void register_builtin_methods(const MethodSink& add);

}  // namespace lfnet::recon
