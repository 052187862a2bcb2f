#include "lfnet/nn/script.h"

#include <torch/script.h>
#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <filesystem>
#include <fstream>

#include "lfnet/core/error.h"
#include "support/small_nets.h"
#include "support/test_support.h"

using lfnet::nn::LightFieldNet;
using lfnet::nn::NetworkOptions;
using lfnet::nn::ScriptMetadata;

namespace {

// Per-pixel patch matrices (sparse, like asp or a mask) or dense Gaussian ones.
torch::Tensor make_stack(const NetworkOptions& o, int64_t phases, bool per_pixel, uint64_t seed) {
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(seed);
  const int64_t n = o.measurements, uv = o.patch.rows * o.patch.cols, hw = o.patch.pixels();
  if (!per_pixel) {
    return torch::randn({phases, n * hw, uv * hw}, gen) / std::sqrt(static_cast<double>(uv * hw));
  }
  auto w = torch::rand({phases, n, 1, uv, hw}, gen) * 2.0 / static_cast<double>(uv);
  auto eye = torch::eye(hw).view({1, 1, hw, 1, hw});
  // (P, N, hw, UV, hw) -> rows (n, pixel), columns (view, pixel)
  return (w * eye).reshape({phases, n * hw, uv * hw}).contiguous();
}

struct Variant {
  std::string name;
  NetworkOptions options;
  int64_t period = 1;
  bool per_pixel = true;
};

std::vector<Variant> variants() {
  std::vector<Variant> v;
  v.push_back({"net, per-pixel Phi, auto", lfnet::test::small_network_options("net")});
  {
    Variant x{"net, 4 phases, pinv residual, stacked", lfnet::test::small_network_options("net"),
              2};
    lfnet::test::edit_paper(x.options, [&](lfnet::nn::PaperOptions& p) {
      p.residual = lfnet::nn::Residual::kPinv;
      p.conv_algorithm = lfnet::nn::Conv4dAlgorithm::kStacked;
    });
    v.push_back(x);
  }
  {
    Variant x{"net, dense Phi, adjoint residual, fused_input, weights not summing to 1",
              lfnet::test::small_network_options("net"), 1, false};
    lfnet::test::edit_paper(x.options, [&](lfnet::nn::PaperOptions& p) {
      p.residual = lfnet::nn::Residual::kAdjoint;
      p.conv_algorithm = lfnet::nn::Conv4dAlgorithm::kFusedInput;
      p.head_weights = {0.7, 0.6};
    });
    v.push_back(x);
  }
  {
    Variant x{"ae on the adjoint, 4 phases, fused_output", lfnet::test::small_network_options("ae"),
              2};
    lfnet::test::edit_paper(x.options, [&](lfnet::nn::PaperOptions& p) {
      p.ae.input = lfnet::nn::AeInput::kAdjoint;
      p.conv_algorithm = lfnet::nn::Conv4dAlgorithm::kFusedOutput;
    });
    v.push_back(x);
  }
  {
    Variant x{"cnn, 9 phases, dense Phi, pinv residual, kernel 5",
              lfnet::test::small_network_options("cnn"), 3, false};
    lfnet::test::edit_paper(x.options, [&](lfnet::nn::PaperOptions& p) {
      p.residual = lfnet::nn::Residual::kPinv;
      p.kernel = 5;
    });
    v.push_back(x);
  }
  return v;
}

ScriptMetadata metadata_for(int64_t period) {
  ScriptMetadata meta;
  meta.phi = {{"name", "synthetic"}, {"n", 2}, {"seed", 3}};
  meta.config = {{"measurement_mean", 0.25}};
  meta.period = period;
  return meta;
}

double max_abs_diff(const torch::Tensor& a, const torch::Tensor& b) {
  return (a - b).abs().max().item<double>();
}

}  // namespace

TEST_CASE("an exported net gives the C++ net's outputs, in memory and after a round trip",
          "[nn][script]") {
  lfnet::test::TempDir tmp;
  int index = 0;
  for (const auto& variant : variants()) {
    INFO(variant.name);
    torch::manual_seed(10 + index);
    LightFieldNet net(variant.options);
    const int64_t phases = variant.period * variant.period;
    net->set_phi(make_stack(variant.options, phases, variant.per_pixel, 20 + index));
    net->eval();
    const auto meta = metadata_for(variant.period);
    const std::string path = tmp / ("net" + std::to_string(index++) + ".pt");
    lfnet::nn::export_network(net, meta, path);
    CHECK(lfnet::nn::is_script_file(path));
    const auto loaded = lfnet::nn::load_script(path);
    CHECK(loaded.network.to_json() == variant.options.to_json());
    CHECK(loaded.meta.phi == meta.phi);
    CHECK(loaded.meta.config == meta.config);
    CHECK(loaded.meta.period == variant.period);
    auto in_memory = lfnet::nn::script_network(net, meta);

    const int64_t b = 37;
    auto y = torch::rand({b, variant.options.measurement_size()});
    auto phase = torch::randint(phases, {b}, torch::kInt64);
    torch::Tensor ph = phases == 1 ? torch::Tensor() : phase;
    torch::NoGradGuard no_grad;
    auto parts = net->forward_all(y, ph);
    const auto shape = std::vector<int64_t>{b, 3, 3, 5, 5};
    auto want = parts.output.reshape(shape);
    CHECK(want.std().item<double>() > 1e-3);  // a net that does something
    auto got = loaded.forward(y, ph);
    REQUIRE(got.sizes() == torch::IntArrayRef(shape));
    CHECK(max_abs_diff(got, want) <= 1e-5);
    // The graph executor profiles the first calls and runs an optimised graph after them.
    for (int call = 0; call < 4; ++call) {
      auto yc = torch::rand({b, variant.options.measurement_size()});
      CHECK(max_abs_diff(loaded.forward(yc, ph), net->forward(yc, ph).reshape(shape)) <= 1e-5);
    }
    const c10::IValue ph_value = ph.defined() ? c10::IValue(ph) : c10::IValue();
    CHECK(max_abs_diff(in_memory.forward({y, ph_value}).toTensor(), want) <= 1e-5);
    // The measurement vector may also come as (B, N, h, w) crops.
    CHECK(max_abs_diff(loaded.forward(y.view({b, 2, 5, 5}), ph), want) <= 1e-5);
    // Branch outputs as network_solver gives them: the branch plus the residual base.
    for (const std::string branch : {"ae", "cnn"}) {
      const auto& t = branch == "ae" ? parts.ae : parts.cnn;
      if (!t.defined()) {
        CHECK_THROWS_WITH(loaded.forward(y, ph, branch),
                          Catch::Contains("has no '" + branch + "' branch"));
        continue;
      }
      auto branch_want = variant.options.branches() == lfnet::nn::Branches::kNet
                             ? (parts.base.defined() ? t + parts.base : t)
                             : parts.output;
      CHECK(max_abs_diff(loaded.forward(y, ph, branch), branch_want.reshape(shape)) <= 1e-5);
    }
    // The Phi stack comes back bit for bit, however it was stored.
    CHECK(torch::equal(loaded.module.get_method("phi_stack")({}).toTensor(), net->phi));
    // Parameters keep their checkpoint names.
    std::map<std::string, torch::Tensor> params;
    for (const auto& p : loaded.module.named_parameters()) params[p.name] = p.value;
    for (const auto& p : net->named_parameters()) {
      INFO(p.key());
      REQUIRE(params.count(p.key()));
      CHECK(torch::equal(params[p.key()], p.value()));
      CHECK_FALSE(params[p.key()].requires_grad());
    }
    CHECK(params.size() == net->named_parameters().size());
  }
}

TEST_CASE("an exported net differs from another net's export", "[nn][script]") {
  // The comparisons above are not vacuous: two random nets differ by far more than 1e-5.
  auto o = lfnet::test::small_network_options("net");
  torch::manual_seed(1);
  LightFieldNet a(o);
  torch::manual_seed(2);
  LightFieldNet b(o);
  auto stack = make_stack(o, 1, true, 5);
  a->set_phi(stack);
  b->set_phi(stack);
  auto sa = lfnet::nn::script_network(a, metadata_for(1));
  torch::NoGradGuard no_grad;
  auto y = torch::rand({8, o.measurement_size()});
  CHECK(max_abs_diff(sa.forward({y}).toTensor(), b->forward(y).reshape({8, 3, 3, 5, 5})) > 1e-3);
}

TEST_CASE("exported files store sparse Phi stacks compactly and carry their metadata",
          "[nn][script]") {
  lfnet::test::TempDir tmp;
  auto o = lfnet::test::small_network_options("net");
  LightFieldNet net(o);
  net->set_phi(make_stack(o, 4, true, 1));
  auto m = lfnet::nn::script_network(net, metadata_for(2));
  CHECK(m.hasattr("phi_index"));
  CHECK_FALSE(m.hasattr("phi"));
  CHECK(m.attr("phi_values").toTensor().numel() == int64_t{4} * 2 * 25 * 9);
  CHECK(m.attr("format_version").toInt() == lfnet::nn::kScriptFormatVersion);
  CHECK(m.attr("period").toInt() == 2);
  CHECK(m.attr("measurements").toInt() == 2);
  CHECK(m.attr("patch_shape").toIntVector() == std::vector<int64_t>{3, 3, 5, 5});
  CHECK(nlohmann::json::parse(m.attr("phi_spec").toStringRef()) == metadata_for(2).phi);
  const auto meta = nlohmann::json::parse(m.attr("metadata").toStringRef());
  CHECK(meta.at("format") == "lfnet-torchscript");
  CHECK(meta.at("phases") == 4);
  CHECK(meta.at("network") == o.to_json());

  // A dense stack is stored as it is.
  net->set_phi(make_stack(o, 1, false, 1));
  auto dense = lfnet::nn::script_network(net, metadata_for(1));
  CHECK(dense.hasattr("phi"));
  CHECK_FALSE(dense.hasattr("phi_index"));

  // The extra file holds the same JSON, readable without lfnet.
  const std::string path = tmp / "m.pt";
  net->set_phi(make_stack(o, 4, true, 1));
  lfnet::nn::export_network(net, metadata_for(2), path);
  torch::jit::ExtraFilesMap extra{{lfnet::nn::kScriptMetadataFile, ""}};
  torch::jit::load(path, torch::kCPU, extra);
  CHECK(nlohmann::json::parse(extra[lfnet::nn::kScriptMetadataFile]) == meta);
  // Nothing but the file is left beside it.
  CHECK(std::distance(std::filesystem::directory_iterator(tmp.path()),
                      std::filesystem::directory_iterator()) == 1);
}

TEST_CASE("exported nets report bad inputs, and bad files are clear errors", "[nn][script]") {
  lfnet::test::TempDir tmp;
  auto o = lfnet::test::small_network_options("net");
  LightFieldNet net(o);
  net->set_phi(make_stack(o, 4, true, 1));
  // Metadata that does not fit the net.
  CHECK_THROWS_AS(lfnet::nn::script_network(net, metadata_for(1)), lfnet::ConfigError);
  const std::string path = tmp / "m.pt";
  lfnet::nn::export_network(net, metadata_for(2), path);
  const auto loaded = lfnet::nn::load_script(path);
  CHECK_THROWS_WITH(loaded.forward(torch::rand({4, 49}), torch::zeros({4}, torch::kInt64)),
                    Catch::Contains("expected measurements (B, 50)"));
  CHECK_THROWS_WITH(loaded.forward(torch::rand({4, 50})), Catch::Contains("4 phases"));
  CHECK_THROWS_WITH(loaded.forward(torch::rand({4, 50}), torch::full({4}, 4, torch::kInt64)),
                    Catch::Contains("phases must lie in [0, 4)"));
  CHECK_THROWS_WITH(lfnet::nn::check_script_phi(loaded, {{"name", "asp"}}),
                    Catch::Contains("trained for Phi"));
  lfnet::nn::check_script_phi(loaded, metadata_for(2).phi);

  // Not a file, not TorchScript, TorchScript without lfnet metadata, another version.
  CHECK_THROWS_AS(lfnet::nn::load_script(tmp / "missing.pt"), lfnet::IoError);
  std::ofstream(tmp / "text.pt") << "LFNETCKP not a zip";
  CHECK_FALSE(lfnet::nn::is_script_file(tmp / "text.pt"));
  CHECK_THROWS_WITH(lfnet::nn::load_script(tmp / "text.pt"), Catch::Contains("not a TorchScript"));
  torch::jit::Module plain("__torch__.Plain");
  plain.register_buffer("x", torch::ones({1}));
  plain.save(tmp / "plain.pt");
  CHECK_THROWS_WITH(lfnet::nn::load_script(tmp / "plain.pt"),
                    Catch::Contains("without lfnet metadata"));
  auto m = lfnet::nn::script_network(net, metadata_for(2));
  auto meta = nlohmann::json::parse(m.attr("metadata").toStringRef());
  meta["format_version"] = 99;
  m.save(tmp / "future.pt", {{lfnet::nn::kScriptMetadataFile, meta.dump()}});
  CHECK_THROWS_WITH(lfnet::nn::load_script(tmp / "future.pt"),
                    Catch::Contains("format version 99"));
}
