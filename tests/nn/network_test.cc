#include "lfnet/nn/network.h"

#include <torch/torch.h>
#include <catch2/catch.hpp>

#include <set>

#include "lfnet/core/error.h"
#include "support/small_nets.h"
#include "support/test_support.h"

using lfnet::nn::LightFieldNet;
using lfnet::nn::NetworkOptions;

namespace {

// A small geometry that keeps the tests fast: 3 x 3 views of 5 x 5 pixels, N = 2.
torch::Tensor random_phi(const NetworkOptions& o, int64_t phases, uint64_t seed) {
  auto gen = torch::make_generator<at::CPUGeneratorImpl>(seed);
  return torch::rand({phases, o.measurement_size(), o.patch.size()}, gen) /
         static_cast<double>(o.patch.rows * o.patch.cols);
}

}  // namespace

TEST_CASE("each branch and the two-branch net give (B, 1, U, V, h, w)", "[nn][network]") {
  torch::manual_seed(0);
  for (const std::string branches : {"ae", "cnn", "net"}) {
    INFO(branches);
    NetworkOptions o;  // defaults: 5 x 5 x 9 x 9 patches, N = 2
    lfnet::test::edit_paper(o, [&](lfnet::nn::PaperOptions& p) {
      p.branches = lfnet::nn::from_string(branches, p.branches);
    });
    LightFieldNet net(o);
    net->set_phi(random_phi(o, 1, 1));
    auto y = torch::rand({3, 162});
    auto out = net->forward_all(y);
    CHECK(out.output.sizes() == torch::IntArrayRef({3, 1, 5, 5, 9, 9}));
    CHECK(out.ae.defined() == (branches != "cnn"));
    CHECK(out.cnn.defined() == (branches != "ae"));
    if (out.ae.defined()) CHECK(out.ae.sizes() == out.output.sizes());
    if (out.cnn.defined()) CHECK(out.cnn.sizes() == out.output.sizes());
  }
}

TEST_CASE("the default net has the documented parameter count and names", "[nn][network]") {
  const NetworkOptions defaults;
  LightFieldNet net(defaults);
  const int64_t ae = (162 * 256 + 256) + (256 * 128 + 128) + (128 * 256 + 256) + (256 * 128 + 128) +
                     (128 * 256 + 256) + (256 * 2025 + 2025) + (81 + 1);
  const int64_t cnn = (16 * 81 + 16) + 3 * (16 * 16 * 81 + 16) + (16 * 81 + 1);
  CHECK(lfnet::nn::parameter_count(*lfnet::nn::ae_branch(*net)) == ae);
  CHECK(lfnet::nn::parameter_count(*lfnet::nn::cnn_branch(*net)) == cnn);
  CHECK(lfnet::nn::parameter_count(*net) == ae + cnn);
  std::set<std::string> names;
  for (const auto& p : net->named_parameters()) names.insert(p.key());
  for (const auto& b : net->named_buffers()) names.insert(b.key());
  std::set<std::string> want = {"phi", "adjoint_scale", "ae.conv.weight", "ae.conv.bias"};
  for (int i = 1; i <= 6; ++i) {
    want.insert("ae.fc" + std::to_string(i) + ".weight");
    want.insert("ae.fc" + std::to_string(i) + ".bias");
  }
  for (int i = 1; i <= 5; ++i) {
    want.insert("cnn.conv" + std::to_string(i) + ".weight");
    want.insert("cnn.conv" + std::to_string(i) + ".bias");
  }
  CHECK(names == want);
}

TEST_CASE("the head averages the branch outputs with the configured weights", "[nn][network]") {
  for (auto weights : std::vector<std::vector<double>>{{0.5, 0.5}, {0.3, 0.9}, {1.0, 0.0}}) {
    INFO(weights[0] << ", " << weights[1]);
    torch::manual_seed(1);
    auto o = lfnet::test::small_network_options("net");
    lfnet::test::edit_paper(o, [&](lfnet::nn::PaperOptions& p) { p.head_weights = weights; });
    LightFieldNet net(o);
    net->set_phi(random_phi(o, 1, 2));
    auto y = torch::rand({4, o.measurement_size()});
    auto out = net->forward_all(y);
    // The branches evaluated on their own, independently of the head.
    auto ae = lfnet::nn::ae_branch(*net)->forward(y);
    auto cnn = lfnet::nn::cnn_branch(*net)->forward(net->adjoint(y).view({4, 1, 3, 3, 5, 5}));
    lfnet::test::require_close(out.ae, ae, 0);
    lfnet::test::require_close(out.cnn, cnn, 0);
    lfnet::test::require_close(out.output, weights[0] * ae + weights[1] * cnn, 1e-6);
    CHECK((ae - cnn).abs().max().item<double>() > 1e-3);  // the weights are visible
  }
}

TEST_CASE("the phi buffer drives the CNN branch, the measurement AE ignores it", "[nn][network]") {
  torch::manual_seed(2);
  auto o = lfnet::test::small_network_options("net");
  LightFieldNet net(o);
  auto y = torch::rand({5, o.measurement_size()});
  net->set_phi(random_phi(o, 1, 3));
  auto first = net->forward_all(y);
  net->set_phi(random_phi(o, 1, 4));
  auto second = net->forward_all(y);
  CHECK((first.cnn - second.cnn).abs().max().item<double>() > 1e-4);
  lfnet::test::require_close(first.ae, second.ae, 0);

  // Then the AE reads Phi^T y and changes too.
  lfnet::test::edit_paper(
      o, [](lfnet::nn::PaperOptions& p) { p.ae.input = lfnet::nn::AeInput::kAdjoint; });
  LightFieldNet net2(o);
  net2->set_phi(random_phi(o, 1, 3));
  auto a = net2->forward_all(y).ae;
  net2->set_phi(random_phi(o, 1, 4));
  CHECK((a - net2->forward_all(y).ae).abs().max().item<double>() > 1e-5);
}

TEST_CASE("the scaled adjoint is s_p Phi_p^T y for each patch's phase", "[nn][network]") {
  torch::manual_seed(3);
  auto o = lfnet::test::small_network_options("cnn");
  LightFieldNet net(o);
  auto stack = random_phi(o, 4, 5);
  net->set_phi(stack);
  REQUIRE(net->phases() == 4);
  auto y = torch::rand({9, o.measurement_size()});
  auto phase = torch::tensor({3, 0, 1, 3, 2, 2, 0, 3, 1}, torch::kInt64);
  auto got = net->adjoint(y, phase);
  for (int64_t i = 0; i < 9; ++i) {
    const int64_t p = phase[i].item<int64_t>();
    auto a = stack[p].to(torch::kFloat64);
    auto t = a.t().matmul(a.sum(1));  // Phi^T Phi 1
    const double s = t.sum().item<double>() / t.square().sum().item<double>();
    lfnet::test::require_close(got[i], s * y[i].to(torch::kFloat64).matmul(a), 1e-5, 1e-5);
  }
  CHECK_THROWS_WITH(net->forward(y), Catch::Contains("4 phases"));
  CHECK_THROWS_WITH(net->forward(y, phase + 1), Catch::Contains("[0, 4)"));
}

TEST_CASE("the adjoint of a flat patch under a view-averaging Phi is the flat patch",
          "[nn][network]") {
  auto o = lfnet::test::small_network_options("cnn");
  o.measurements = 1;
  // One measurement per pixel: the mean of its 9 views.
  const int64_t views = 9, pixels = 25;
  auto phi = torch::zeros({1, pixels, views * pixels});
  for (int64_t px = 0; px < pixels; ++px) {
    for (int64_t v = 0; v < views; ++v) phi[0][px][v * pixels + px] = 1.0 / views;
  }
  LightFieldNet net(o);
  net->set_phi(phi);
  auto lf = torch::full({1, views * pixels}, 0.7);
  auto y = lf.matmul(phi[0].t());
  lfnet::test::require_close(net->adjoint(y), lf, 1e-6);
}

TEST_CASE("the pinv residual adds the Tikhonov pseudo-inverse estimate", "[nn][network]") {
  torch::manual_seed(4);
  auto o = lfnet::test::small_network_options("ae");
  lfnet::test::edit_paper(
      o, [&](lfnet::nn::PaperOptions& p) { p.residual = lfnet::nn::Residual::kPinv; });
  o.pinv_lambda = 1e-2;
  LightFieldNet net(o);
  auto stack = random_phi(o, 2, 6);
  net->set_phi(stack);
  auto y = torch::rand({3, o.measurement_size()});
  auto phase = torch::tensor({1, 0, 1}, torch::kInt64);
  auto out = net->forward_all(y, phase);
  for (int64_t i = 0; i < 3; ++i) {
    // (Phi^T Phi + lambda I)^-1 Phi^T y, solved in the light-field space (D x D).
    auto a = stack[phase[i].item<int64_t>()].to(torch::kFloat64);
    auto d = a.size(1);
    auto want = torch::linalg_solve(a.t().matmul(a) + 1e-2 * torch::eye(d, torch::kFloat64),
                                    a.t().matmul(y[i].to(torch::kFloat64)));
    lfnet::test::require_close(out.base[i].reshape({-1}), want, 1e-4, 1e-4);
  }
  lfnet::test::require_close(out.output, out.ae + out.base, 1e-6);
}

TEST_CASE("Phi switching maps measurement weights through the new Phi's pseudo-inverse",
          "[nn][network]") {
  torch::manual_seed(5);
  const int64_t m = 6, d = 20, hidden = 4;
  auto phi_a = torch::randn({m, d}, torch::kFloat64);
  auto w = torch::randn({hidden, m}, torch::kFloat64);
  // The same measurements in another order: the mapped weights are the permuted columns.
  auto perm = torch::tensor({2, 0, 5, 1, 4, 3}, torch::kInt64);
  auto phi_b = phi_a.index_select(0, perm);
  auto mapped = lfnet::nn::map_measurement_weights(w, phi_a, phi_b, 1e-9);
  lfnet::test::require_close(mapped, w.index_select(1, perm), 1e-6);
  // Another Phi with more measurements: W_B Phi_B l = W_A Phi_A l for l in Phi_B's row space.
  auto phi_c = torch::randn({9, d}, torch::kFloat64);
  auto mapped_c = lfnet::nn::map_measurement_weights(w, phi_a, phi_c, 1e-9);
  REQUIRE(mapped_c.sizes() == torch::IntArrayRef({hidden, 9}));
  auto l = phi_c.t().matmul(torch::randn({9}, torch::kFloat64));  // in the row space
  lfnet::test::require_close(mapped_c.matmul(phi_c.matmul(l)), w.matmul(phi_a.matmul(l)), 1e-6,
                             1e-6);
}

TEST_CASE("network options parse strictly, round-trip and validate", "[nn][network]") {
  auto j = nlohmann::json::parse(R"({"patch": {"rows": 3, "cols": 3, "height": 7, "width": 7},
      "measurements": 4, "paper": {"branches": "cnn", "ae": {"hidden": [10, 5, 10, 5, 10]},
      "cnn": {"channels": 8, "depth": 2}, "head_weights": [0.25, 0.75], "residual": "pinv"}})");
  auto o = NetworkOptions::from_json(j);
  CHECK(o.patch.size() == int64_t{3} * 3 * 7 * 7);
  CHECK(o.measurement_size() == int64_t{4} * 49);
  const auto paper = lfnet::nn::paper_options(o);
  CHECK(paper.cnn.channels == 8);
  CHECK(paper.head_weights[1] == 0.75);
  CHECK(o.branches() == lfnet::nn::Branches::kCnn);
  CHECK_FALSE(o.has_ae());
  CHECK(NetworkOptions::from_json(o.to_json()).to_json() == o.to_json());
  // A file holds the section in full: the keys not given, at their defaults.
  CHECK(o.to_json()["paper"]["kernel"] == 3);
  CHECK(o.to_json()["paper"]["conv_algorithm"] == "auto");
  // Options not yet checked still print, an unknown architecture's too.
  NetworkOptions unknown;
  unknown.architecture = "nosuch";
  CHECK(unknown.to_json()["architecture"] == "nosuch");
  CHECK_FALSE(unknown.to_json().contains("paper"));

  CHECK_THROWS_WITH(
      NetworkOptions::from_json(nlohmann::json::parse(R"({"paper": {"cnn": {"chanels": 3}}})"),
                                "$.network"),
      Catch::Contains("$.network.paper.cnn.chanels"));
  CHECK_THROWS_WITH(
      NetworkOptions::from_json(nlohmann::json::parse(R"({"paper": {"branches": "both"}})")),
      Catch::Contains("$.paper.branches") && Catch::Contains("net, ae, cnn"));
  CHECK_THROWS_WITH(
      NetworkOptions::from_json(nlohmann::json::parse(R"({"paper": {"ae": {"hidden": [1, 2]}}})")),
      Catch::Contains("$.paper.ae.hidden"));
  CHECK_THROWS_WITH(NetworkOptions::from_json(nlohmann::json::parse(R"({"paper": {"kernel": 2}})")),
                    Catch::Contains("$.paper.kernel"));
  // The paper's keys at the top level, as files held them before the section: a config is told
  // where they go; a checkpoint's are read as the section.
  CHECK_THROWS_WITH(
      NetworkOptions::from_json(nlohmann::json::parse(R"({"kernel": 5})"), "$.network"),
      Catch::Contains("$.network.kernel") && Catch::Contains("$.network.paper.kernel"));
  const auto old = nlohmann::json::parse(R"({"measurements": 4, "branches": "ae",
      "patch": {"rows": 5, "cols": 5, "height": 16, "width": 16},
      "cnn": {"channels": 8, "depth": 2}, "residual": "pinv", "image": {"channels": 32}})");
  const auto read = NetworkOptions::from_file_json(old);
  CHECK(read.branches() == lfnet::nn::Branches::kAe);
  CHECK(lfnet::nn::paper_options(read).cnn.channels == 8);
  CHECK(lfnet::nn::paper_options(read).residual == lfnet::nn::Residual::kPinv);
  CHECK_FALSE(read.to_json().contains("image"));
  CHECK_FALSE(read.to_json().contains("residual"));
  // Another architecture's file drops them.
  auto old_lfnet = old;
  old_lfnet["architecture"] = "lfnet";
  const auto lfnet_read = NetworkOptions::from_file_json(old_lfnet);
  CHECK(lfnet_read.branches() == lfnet::nn::Branches::kNet);
  CHECK_FALSE(lfnet_read.has_ae());
  CHECK_FALSE(lfnet_read.to_json().contains("paper"));
  CHECK(lfnet_read.to_json()["image"]["channels"] == 32);
  // A paper section given to another architecture is refused.
  CHECK_THROWS_WITH(NetworkOptions::from_json(nlohmann::json::parse(
                        R"({"architecture": "lfnet", "paper": {"kernel": 5}})")),
                    Catch::Contains("paper") && Catch::Contains("another architecture"));
  auto lfnet_options = lfnet_read;
  CHECK_THROWS_WITH(lfnet_options.set_branches(lfnet::nn::Branches::kAe),
                    Catch::Contains("no branches"));
  CHECK_THROWS_AS(NetworkOptions::from_json(nlohmann::json::parse(R"({"measurements": "2"})")),
                  lfnet::ConfigError);
}

TEST_CASE("the net rejects measurement vectors and Phi stacks of the wrong size", "[nn][network]") {
  auto o = lfnet::test::small_network_options("net");
  LightFieldNet net(o);
  CHECK_THROWS_WITH(net->forward(torch::rand({2, 7})), Catch::Contains("(B, 50)"));
  CHECK_THROWS_WITH(net->set_phi(torch::rand({1, 50, 80})), Catch::Contains("(P, 50, 225)"));
  auto bad = random_phi(o, 1, 1);
  bad[0][0][0] = std::nan("");
  CHECK_THROWS_AS(net->set_phi(bad), lfnet::NumericalError);
}

TEST_CASE("the net trains: gradients reach every parameter", "[nn][network]") {
  torch::manual_seed(6);
  auto o = lfnet::test::small_network_options("net");
  LightFieldNet net(o);
  net->set_phi(random_phi(o, 1, 7));
  auto y = torch::rand({4, o.measurement_size()});
  net->forward(y).square().sum().backward();
  for (const auto& p : net->named_parameters()) {
    INFO(p.key());
    REQUIRE(p.value().grad().defined());
    CHECK(p.value().grad().abs().sum().item<double>() > 0);
  }
  for (const auto& b : net->named_buffers()) CHECK_FALSE(b.value().requires_grad());
}

TEST_CASE("forward_all runs only the selected branches", "[nn][network]") {
  auto o = lfnet::test::small_network_options("net");
  lfnet::test::edit_paper(
      o, [&](lfnet::nn::PaperOptions& p) { p.residual = lfnet::nn::Residual::kPinv; });
  torch::manual_seed(5);
  LightFieldNet net(o);
  net->set_phi(random_phi(o, 2, 11));
  auto y = torch::rand({6, o.measurement_size()});
  auto phase = torch::tensor({0, 1, 1, 0, 1, 0}, torch::kInt64);
  torch::NoGradGuard no_grad;
  auto all = net->forward_all(y, phase);
  lfnet::nn::BranchSelection ae_only;
  ae_only.cnn = false;
  auto ae = net->forward_all(y, phase, ae_only);
  CHECK_FALSE(ae.cnn.defined());
  lfnet::test::require_close(ae.ae, all.ae, 0.0);
  lfnet::test::require_close(ae.output, all.ae + all.base, 1e-6);
  lfnet::nn::BranchSelection cnn_only;
  cnn_only.ae = false;
  auto cnn = net->forward_all(y, phase, cnn_only);
  CHECK_FALSE(cnn.ae.defined());
  lfnet::test::require_close(cnn.output, all.cnn + all.base, 1e-6);
  // Neither: the residual base alone (the fully convolutional path's per-patch part).
  lfnet::nn::BranchSelection none;
  none.ae = none.cnn = false;
  auto base = net->forward_all(y, phase, none);
  CHECK_FALSE(base.ae.defined());
  CHECK_FALSE(base.cnn.defined());
  lfnet::test::require_close(base.output, all.base, 0.0);
  // Both selected: the same as the default.
  lfnet::test::require_close(net->forward_all(y, phase, {}).output, all.output, 0.0);
}

TEST_CASE("the CNN branch in bfloat16 stays close to float32 and keeps float32 outside",
          "[nn][network]") {
  auto o = lfnet::test::small_network_options("net");
  torch::manual_seed(6);
  LightFieldNet net(o);
  net->set_phi(random_phi(o, 1, 12));
  auto y = torch::rand({8, o.measurement_size()});
  torch::NoGradGuard no_grad;
  auto want = net->forward_all(y);
  lfnet::nn::set_cnn_precision(net, lfnet::nn::Precision::kBFloat16);
  CHECK(lfnet::nn::cnn_branch(*net)->convs[0]->weight.scalar_type() == torch::kBFloat16);
  CHECK(lfnet::nn::ae_branch(*net)->fc[0]->weight.scalar_type() == torch::kFloat32);
  auto got = net->forward_all(y);
  REQUIRE(got.output.scalar_type() == torch::kFloat32);
  // bfloat16 keeps 8 mantissa bits: relative error ~2^-8 per rounding.
  const double scale = want.cnn.abs().max().item<double>();
  const double err = (got.cnn - want.cnn).abs().max().item<double>();
  CHECK(err > 0.0);
  CHECK(err < 0.03 * scale);
  lfnet::test::require_close(got.ae, want.ae, 0.0);
  lfnet::nn::set_cnn_precision(net, lfnet::nn::Precision::kFloat32);
  CHECK(lfnet::nn::cnn_branch(*net)->convs[0]->weight.scalar_type() == torch::kFloat32);
  CHECK(lfnet::nn::parse_precision("bfloat16") == lfnet::nn::Precision::kBFloat16);
  CHECK(lfnet::nn::to_string(lfnet::nn::Precision::kFloat32) == "float32");
  CHECK_THROWS_AS(lfnet::nn::parse_precision("half"), lfnet::ConfigError);
}
