#include "lfnet/train/trainer.h"

#include <ATen/CPUGeneratorImpl.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <optional>
#include <sstream>
#include <string_view>

#include "lfnet/core/enum_names.h"
#include "lfnet/core/error.h"
#include "lfnet/core/json.h"
#include "lfnet/core/progress.h"
#include "lfnet/core/runtime.h"
#include "lfnet/nn/architecture.h"
#include "lfnet/train/joint_phi.h"

namespace lfnet::train {

namespace {

std::string param_key(const torch::Tensor& p) {
  return c10::guts::to_string(p.unsafeGetTensorImpl());
}

// The global L2 norm of the gradients (NaN or inf when any is).
double gradient_norm(const torch::nn::Module& module) {
  torch::NoGradGuard no_grad;
  auto total = torch::zeros({}, torch::kFloat64);
  for (const auto& p : module.parameters()) {
    if (p.grad().defined()) total += p.grad().to(torch::kFloat64).square().sum();
  }
  return std::sqrt(total.item<double>());
}

bool all_finite(const torch::Tensor& t) {
  return !t.defined() || torch::isfinite(t).all().item<bool>();
}

std::string format_double(double v) {
  std::ostringstream out;
  out << v;
  return out.str();
}

}  // namespace

// ---- options -------------------------------------------------------------------------------

namespace {
constexpr EnumName<Stage> kStages[] = {
    {Stage::kAe, "ae"}, {Stage::kCnn, "cnn"}, {Stage::kJoint, "joint"}};
constexpr EnumName<ScheduleKind> kSchedules[] = {{ScheduleKind::kConstant, "constant"},
                                                 {ScheduleKind::kStep, "step"},
                                                 {ScheduleKind::kCosine, "cosine"}};
constexpr EnumName<OnNonFinite> kOnNonFinite[] = {{OnNonFinite::kStop, "stop"},
                                                  {OnNonFinite::kSkip, "skip"}};
}  // namespace

std::string to_string(Stage value) { return name_of(value, kStages); }
std::string to_string(ScheduleKind value) { return name_of(value, kSchedules); }
std::string to_string(OnNonFinite value) { return name_of(value, kOnNonFinite); }
Stage from_string(const std::string& name, Stage) { return value_of(name, kStages); }
ScheduleKind from_string(const std::string& name, ScheduleKind) {
  return value_of(name, kSchedules);
}
OnNonFinite from_string(const std::string& name, OnNonFinite) {
  return value_of(name, kOnNonFinite);
}

nn::Branches branches_of_stage(Stage stage) {
  switch (stage) {
    case Stage::kAe:
      return nn::Branches::kAe;
    case Stage::kCnn:
      return nn::Branches::kCnn;
    case Stage::kJoint:
      break;
  }
  return nn::Branches::kNet;
}

void LrScheduleOptions::read(JsonReader& reader) { read_fields(reader, *this); }

nlohmann::json LrScheduleOptions::to_json() const { return fields_to_json(*this); }

void LrScheduleOptions::validate() const {
  if (step_epochs < 1) throw ConfigError("step_epochs: must be >= 1");
  if (!(gamma > 0) || !std::isfinite(gamma)) throw ConfigError("gamma: must be positive");
  if (!(min_factor >= 0 && min_factor <= 1)) throw ConfigError("min_factor: must lie in [0, 1]");
  if (warmup_epochs < 0) throw ConfigError("warmup_epochs: must be >= 0");
}

TrainerOptions TrainerOptions::from_json(const nlohmann::json& j, const std::string& path) {
  TrainerOptions options;
  JsonReader reader(j, path);
  options.read(reader);
  reader.finish();
  return options;
}

void TrainerOptions::read(JsonReader& reader) {
  read_fields(reader, *this);
  with_path(reader, [&] { validate(); });
}

nlohmann::json TrainerOptions::to_json() const { return fields_to_json(*this); }

void TrainerOptions::validate() const {
  auto fail = [](const std::string& field, const std::string& what) {
    throw ConfigError(field + ": " + what);
  };
  if (device != "cpu" && device != "cuda" && device.rfind("cuda:", 0) != 0) {
    fail("device", "'" + device + "' is unknown (known: cpu, cuda, cuda:K)");
  }
  if (epochs < 1) fail("epochs", "must be >= 1");
  if (batch_size < 1) fail("batch_size", "must be >= 1");
  if (!(lr > 0) || !std::isfinite(lr)) fail("lr", "must be positive and finite");
  if (!(beta1 >= 0 && beta1 < 1)) fail("beta1", "must lie in [0, 1)");
  if (!(beta2 >= 0 && beta2 < 1)) fail("beta2", "must lie in [0, 1)");
  if (!(eps >= 0)) fail("eps", "must be >= 0");
  if (!(weight_decay >= 0)) fail("weight_decay", "must be >= 0");
  try {
    schedule.validate();
  } catch (const ConfigError& e) {
    throw ConfigError(std::string("schedule.") + e.what());
  }
  if (!(loss.noise_scale >= 0 && std::isfinite(loss.noise_scale))) {
    fail("loss.noise_scale", "must be >= 0");
  }
  if (!(clip_grad_norm >= 0)) fail("clip_grad_norm", "must be >= 0");
  if (max_skipped_batches < 0) fail("max_skipped_batches", "must be >= 0");
}

void CodeTrainingOptions::validate(int64_t epochs) const {
  LFNET_CHECK_AS(ConfigError, lr >= 0 && std::isfinite(lr),
                 "$.code.lr: must be finite and >= 0, got ", lr);
  LFNET_CHECK_AS(ConfigError, freeze_epochs >= 0 && freeze_epochs <= epochs,
                 "$.code.freeze_epochs: must lie in 0..", epochs, " (the stage's epochs), got ",
                 freeze_epochs);
  LFNET_CHECK_AS(ConfigError, !binarise || freeze_epochs >= 1,
                 "$.code.binarise: a binary code is held fixed for the last epochs; set "
                 "$.code.freeze_epochs to at least 1");
  LFNET_CHECK_AS(ConfigError,
                 straight_through_epochs >= 0 && freeze_epochs + straight_through_epochs <= epochs,
                 "$.code.straight_through_epochs: must lie in 0..", epochs - freeze_epochs,
                 " (the epochs before the freeze), got ", straight_through_epochs);
  LFNET_CHECK_AS(ConfigError, straight_through_epochs == 0 || binarise,
                 "$.code.straight_through_epochs: learning through the rounding is for a code "
                 "that is rounded: set $.code.binarise");
}

double learning_rate(const TrainerOptions& options, int64_t epoch, int64_t batch, int64_t batches) {
  const auto& s = options.schedule;
  const double progress =
      (static_cast<double>(epoch) + static_cast<double>(batch) / static_cast<double>(batches)) /
      static_cast<double>(options.epochs);
  double factor = 1.0;
  if (s.name == ScheduleKind::kStep) {
    const int64_t steps_taken = epoch / s.step_epochs;  // whole steps only
    factor = std::pow(s.gamma, static_cast<double>(steps_taken));
  } else if (s.name == ScheduleKind::kCosine) {
    factor = s.min_factor + (1 - s.min_factor) * 0.5 * (1 + std::cos(M_PI * progress));
  }
  const int64_t warmup = s.warmup_epochs * batches, global = epoch * batches + batch;
  if (global < warmup) factor *= static_cast<double>(global + 1) / static_cast<double>(warmup);
  return options.lr * factor;
}

// ---- records -------------------------------------------------------------------------------

nlohmann::json EpochRecord::to_json() const {
  return {{"epoch", epoch},
          {"step", step},
          {"lr", lr},
          {"train_loss", finite_or_null(train_loss)},
          {"val_loss", finite_or_null(val_loss)},
          {"val_psnr_db", finite_or_null(val_psnr_db)},
          {"seconds", seconds},
          {"patches_per_s", patches_per_s},
          {"communication_s", communication_s},
          {"skipped_batches", skipped_batches},
          {"best", best}};
}

EpochRecord EpochRecord::from_json(const nlohmann::json& j) {
  EpochRecord r;
  r.epoch = j.at("epoch").get<int64_t>();
  r.step = j.at("step").get<int64_t>();
  r.lr = j.at("lr").get<double>();
  r.train_loss = number_or(j.at("train_loss"), NAN);
  r.val_loss = number_or(j.at("val_loss"), NAN);
  r.val_psnr_db = number_or(j.at("val_psnr_db"), INFINITY);
  r.seconds = j.at("seconds").get<double>();
  r.patches_per_s = j.at("patches_per_s").get<double>();
  r.communication_s = j.value("communication_s", 0.0);  // absent in records of older runs
  r.skipped_batches = j.at("skipped_batches").get<int64_t>();
  r.best = j.at("best").get<bool>();
  return r;
}

nlohmann::json InitReport::to_json() const {
  return {{"copied", copied.size()},
          {"mapped", mapped},
          {"widened", widened},
          {"deepened", deepened},
          {"reinitialised", reinitialised}};
}

std::string last_checkpoint_path(const std::string& dir) {
  return (std::filesystem::path(dir) / "last.ckpt").string();
}

std::string best_checkpoint_path(const std::string& dir) {
  return (std::filesystem::path(dir) / "best.ckpt").string();
}

// ---- Adam state by name --------------------------------------------------------------------

TensorMap adam_state(const torch::optim::Adam& adam, const torch::nn::Module& module) {
  TensorMap out;
  const auto& state = adam.state();
  for (const auto& p : module.named_parameters()) {
    auto it = state.find(param_key(p.value()));
    if (it == state.end()) continue;
    const auto& s = static_cast<const torch::optim::AdamParamState&>(*it->second);
    out[p.key() + "/exp_avg"] = s.exp_avg().detach().to(torch::kCPU).contiguous().clone();
    out[p.key() + "/exp_avg_sq"] = s.exp_avg_sq().detach().to(torch::kCPU).contiguous().clone();
    out[p.key() + "/step"] = torch::tensor(s.step(), torch::kInt64);
  }
  return out;
}

void load_adam_state(torch::optim::Adam& adam, const torch::nn::Module& module,
                     const TensorMap& state, const std::string& what) {
  auto& target = adam.state();
  target.clear();
  size_t used = 0;
  for (const auto& p : module.named_parameters()) {
    auto m = state.find(p.key() + "/exp_avg"), v = state.find(p.key() + "/exp_avg_sq"),
         step = state.find(p.key() + "/step");
    if (m == state.end() && v == state.end() && step == state.end()) continue;
    if (m == state.end() || v == state.end() || step == state.end() ||
        m->second.sizes() != p.value().sizes() || v->second.sizes() != p.value().sizes()) {
      throw CheckpointError(what + ": the Adam state of " + p.key() +
                            " is incomplete or has the wrong shape");
    }
    auto s = std::make_unique<torch::optim::AdamParamState>();
    s->step(step->second.item<int64_t>());
    s->exp_avg(m->second.to(p.value().device()).clone());
    s->exp_avg_sq(v->second.to(p.value().device()).clone());
    target[param_key(p.value())] = std::move(s);
    used += 3;
  }
  if (used != state.size()) {
    throw CheckpointError(what + ": its Adam state names parameters this network lacks");
  }
}

// ---- trainer -------------------------------------------------------------------------------

namespace {

// The batch on `device` (tensors already there are not copied).
Batch to_device(const Batch& batch, const c10::Device& device) {
  Batch out;
  out.y = batch.y.defined() ? batch.y.to(device) : batch.y;
  out.phase = batch.phase.defined() ? batch.phase.to(device) : batch.phase;
  out.noise = batch.noise.defined() ? batch.noise.to(device) : batch.noise;
  out.target = batch.target.defined() ? batch.target.to(device) : batch.target;
  return out;
}

std::unique_ptr<torch::optim::Adam> make_adam(const nn::LightFieldNet& net,
                                              const TrainerOptions& o) {
  torch::optim::AdamOptions adam(o.lr);
  adam.betas({o.beta1, o.beta2}).eps(o.eps).weight_decay(o.weight_decay);
  return std::make_unique<torch::optim::Adam>(net->parameters(), adam);
}

// A learned code's own Adam: the net's betas and eps, no weight decay.
std::unique_ptr<torch::optim::Adam> make_code_adam(const nn::LearnedPhi& code,
                                                   const TrainerOptions& o,
                                                   const CodeTrainingOptions& c) {
  torch::optim::AdamOptions adam(c.lr);
  adam.betas({o.beta1, o.beta2}).eps(o.eps);
  return std::make_unique<torch::optim::Adam>(code->parameters(), adam);
}

// The noise a learned code's measurements get: training step `step`, or validation batch
// `batch` (the same draws every epoch), each from its own seed.
uint64_t code_noise_seed(int64_t step) {
  return 0x6c666e6574636f64ULL ^ (static_cast<uint64_t>(step) * 0x9E3779B97F4A7C15ULL);
}
uint64_t code_validation_seed(size_t batch) {
  return 0x76616c6964617465ULL + static_cast<uint64_t>(batch);
}

// The module's parameters and buffers under kCodePrefix.
void add_code_state(TensorMap& out, const TensorMap& code) {
  for (const auto& [name, t] : code) out[kCodePrefix + name] = t;
}
// The entries of `state` under kCodePrefix, the prefix taken off.
TensorMap code_part(const TensorMap& state) {
  TensorMap out;
  const std::string prefix = kCodePrefix;
  for (const auto& [name, t] : state) {
    if (name.rfind(prefix, 0) == 0) out[name.substr(prefix.size())] = t;
  }
  return out;
}
TensorMap without_code(const TensorMap& state) {
  TensorMap out;
  for (const auto& [name, t] : state) {
    if (name.rfind(kCodePrefix, 0) != 0) out[name] = t;
  }
  return out;
}

}  // namespace

Trainer::Trainer(nn::LightFieldNet net, TrainerOptions options, RunInfo run)
    : net_(std::move(net)),
      options_(std::move(options)),
      run_(std::move(run)),
      loss_(options_.loss, net_->options().patch.rows, net_->options().patch.cols) {
  options_.validate();
  const auto branches = net_->options().branches();
  LFNET_CHECK_AS(ConfigError, branches_of_stage(options_.stage) == branches, "stage '",
                 to_string(options_.stage), "' trains a net with branches '",
                 nn::to_string(branches_of_stage(options_.stage)), "', but this net has branches '",
                 nn::to_string(branches), "'");
  LFNET_CHECK_AS(ConfigError, run_.phi.is_object() && !run_.phi.empty(),
                 "the run needs the Phi spec of its measurements (RunInfo::phi)");
  LFNET_CHECK(net_->phi.abs().sum().item<double>() > 0,
              "the net's Phi is not set: call set_phi with the patch matrices first");
  device_ = parse_device(options_.device);
  net_->to(device_);
  nn::emulate_precision(net_, options_.precision);
  optimizer_ = make_adam(net_, options_);
  state_.stage = to_string(options_.stage);
  comm_ = std::make_shared<dist::LocalCommunicator>();
}

void Trainer::set_code(nn::LearnedPhi code, CodeTrainingOptions options) {
  LFNET_CHECK(code, "set_code: no code");
  LFNET_CHECK_AS(ConfigError, net_->architecture().learns_code(), "the ",
                 net_->architecture().name(),
                 " architecture cannot learn a code with the net (the lfnet architecture can)");
  options.validate(options_.epochs);
  const auto w = code->weights();
  const auto& o = net_->options();
  LFNET_CHECK_AS(
      ConfigError,
      w.size(0) == o.measurements && w.size(1) == o.patch.rows && w.size(2) == o.patch.cols,
      "the code measures ", w.size(0), " values of ", w.size(1), "x", w.size(2),
      " views, but the net reads ", o.measurements, " of ", o.patch.rows, "x", o.patch.cols);
  LFNET_CHECK_AS(ConfigError, w.size(3) == net_->period(), "the code's period ", w.size(3),
                 " differs from that of the Phi the net and its data were made with (",
                 net_->period(), "): make them with the code's own spec");
  code_ = std::move(code);
  code_->to(device_);
  code_options_ = options;
  code_optimizer_ = make_code_adam(code_, options_, code_options_);
  fixed_code_ = torch::Tensor();
  sync_code_phi();
}

torch::Tensor Trainer::code_weights() const {
  if (!code_) return {};
  if (fixed_code_.defined()) return fixed_code_;
  torch::NoGradGuard no_grad;
  return straight_through_ ? code_->binarised_weights().to(device_) : code_->weights();
}

optics::PhiSpec Trainer::code_phi_spec() const {
  LFNET_CHECK(code_, "code_phi_spec: no code");
  std::string source = "learned " + code_->options().family;
  if ((fixed_code_.defined() || straight_through_) && code_options_.binarise) {
    source += ", binarised";
  }
  // Resolved as every spec a run records is (make_phi fills in what a spec leaves out).
  return optics::make_phi(nn::calibrated_spec(code_weights(), source))->spec();
}

bool Trainer::code_frozen(int64_t epoch) const {
  return code_ && epoch >= options_.epochs - code_options_.freeze_epochs;
}

bool Trainer::code_straight_through(int64_t epoch) const {
  return code_ && !code_frozen(epoch) &&
         epoch >=
             options_.epochs - code_options_.freeze_epochs - code_options_.straight_through_epochs;
}

void Trainer::sync_code_phi() {
  if (!code_) return;
  net_->set_phi(code_weights().detach().to(torch::kCPU, torch::kFloat32));
}

void Trainer::prepare_code(int64_t epoch, BatchSource& source) {
  straight_through_ = code_straight_through(epoch);
  if (!code_frozen(epoch) || fixed_code_.defined()) return;
  torch::NoGradGuard no_grad;
  if (!code_options_.binarise) {
    fixed_code_ = code_->weights().detach();
    sync_code_phi();
    return;
  }
  fixed_code_ = code_->binarised_weights().to(device_);
  if (state_.code.contains("binarised")) {
    sync_code_phi();  // resumed after the rounding: it was measured then
    return;
  }
  // What rounding costs the net as it is, then only binary-code epochs count as best.
  auto rounded = fixed_code_;
  fixed_code_ = code_->weights().detach();
  sync_code_phi();
  const auto before = evaluate(source);
  fixed_code_ = rounded;
  sync_code_phi();
  const auto after = evaluate(source);
  state_.code["binarised"] = {{"epoch", epoch + 1},
                              {"continuous_psnr_db", before.psnr_db},
                              {"binary_psnr_db", after.psnr_db}};
  state_.best_metric = -std::numeric_limits<double>::infinity();
  state_.best_epoch = 0;
}

void Trainer::set_communicator(std::shared_ptr<dist::Communicator> communicator) {
  LFNET_CHECK(communicator != nullptr, "set_communicator: no communicator");
  comm_ = std::move(communicator);
}

void Trainer::synchronise() {
  // The history stays with rank 0, the only rank that writes checkpoints.
  torch::NoGradGuard no_grad;
  auto position = torch::tensor({state_.epoch, state_.step, state_.best_epoch}, torch::kInt64);
  auto best = torch::tensor({state_.best_metric}, torch::kFloat64);
  comm_->broadcast(position);
  comm_->broadcast(best);
  state_.epoch = position[0].item<int64_t>();
  state_.step = position[1].item<int64_t>();
  state_.best_epoch = position[2].item<int64_t>();
  state_.best_metric = best.item<double>();
  for (auto& p : net_->parameters()) {
    auto data = p.detach();
    comm_->broadcast(data);
  }
  for (auto& b : net_->buffers()) {
    auto data = b.detach();
    comm_->broadcast(data);
  }
  // Adam moments: rank 0 says which parameters have them; the others make room, then receive.
  auto& adam = optimizer_->state();
  const auto params = net_->parameters();
  auto has = torch::zeros({static_cast<int64_t>(params.size())}, torch::kInt64);
  for (size_t i = 0; i < params.size(); ++i) {
    has[static_cast<int64_t>(i)] = adam.count(param_key(params[i])) ? 1 : 0;
  }
  comm_->broadcast(has);
  for (size_t i = 0; i < params.size(); ++i) {
    const auto key = param_key(params[i]);
    if (has[static_cast<int64_t>(i)].item<int64_t>() == 0) {
      adam.erase(key);
      continue;
    }
    if (!adam.count(key)) {
      auto fresh = std::make_unique<torch::optim::AdamParamState>();
      fresh->exp_avg(torch::zeros_like(params[i]));
      fresh->exp_avg_sq(torch::zeros_like(params[i]));
      adam[key] = std::move(fresh);
    }
    auto& st = static_cast<torch::optim::AdamParamState&>(*adam.at(key));
    auto m = st.exp_avg(), v = st.exp_avg_sq();
    auto step = torch::tensor({st.step()}, torch::kInt64);
    comm_->broadcast(m);
    comm_->broadcast(v);
    comm_->broadcast(step);
    st.step(step.item<int64_t>());
  }
}

void Trainer::average_gradients(double patches) {
  torch::NoGradGuard no_grad;
  std::vector<torch::Tensor> grads;
  for (auto& p : net_->parameters()) {
    if (!p.grad().defined()) p.mutable_grad() = torch::zeros_like(p);
    grads.push_back(p.grad().reshape({-1}));
  }
  auto flat = torch::cat(grads);
  const Stopwatch clock;
  comm_->all_reduce_sum(flat);
  communication_s_ += clock.seconds();
  flat.div_(patches);
  int64_t offset = 0;
  for (auto& p : net_->parameters()) {
    const int64_t n = p.numel();
    p.mutable_grad().copy_(flat.slice(0, offset, offset + n).view_as(p));
    offset += n;
  }
}

void Trainer::apply_lr(double lr) {
  for (auto& group : optimizer_->param_groups()) group.options().set_lr(lr);
  if (code_optimizer_) {
    // The code follows the net's schedule from its own learning rate.
    const double code_lr = options_.lr > 0 ? code_options_.lr * lr / options_.lr : 0.0;
    for (auto& group : code_optimizer_->param_groups()) group.options().set_lr(code_lr);
  }
}

Checkpoint Trainer::checkpoint() const {
  Checkpoint ck;
  ck.config = run_.config;
  ck.network = net_->options().to_json();
  ck.phi = run_.phi;
  ck.command_line = run_.command_line;
  ck.model = module_state(*net_);
  ck.optimizer = adam_state(*optimizer_, *net_);
  if (code_) {
    // The code as the net uses it is the model's Phi; the net's Phi buffers hold its weights.
    ck.phi = code_phi_spec().to_json();
    add_code_state(ck.model, module_state(*code_));
    add_code_state(ck.optimizer, adam_state(*code_optimizer_, *code_));
  }
  ck.optimizer_options = {{"type", "adam"},          {"lr", options_.lr},
                          {"beta1", options_.beta1}, {"beta2", options_.beta2},
                          {"eps", options_.eps},     {"weight_decay", options_.weight_decay}};
  ck.training = state_;
  auto gen = at::detail::getDefaultCPUGenerator();
  {
    std::lock_guard<std::mutex> lock(gen.mutex());
    ck.training.rng_state = gen.get_state();
  }
  return ck;
}

void Trainer::resume(const std::string& path) {
  const std::string what = "checkpoint " + path;
  auto ck = load_checkpoint(path);
  if (code_) {
    // The Phi is the code, which the checkpoint holds; the code's options must match.
    const auto mine = fields_to_json(code_->options());
    const auto theirs = ck.config.value("code", nlohmann::json());
    if (!ck.model.count(std::string(kCodePrefix) + code_->named_parameters().begin()->key())) {
      throw CheckpointError(what + " holds no learned code: it did not train one");
    }
    for (const auto& [key, value] : mine.items()) {
      if (theirs.is_object() && theirs.contains(key) && theirs[key] != value) {
        std::string message = what;
        message += " trained a code with " + key + " " + theirs[key].dump();
        message += ", this run asks for " + value.dump();
        throw CheckpointError(message);
      }
    }
  } else {
    check_phi(ck, run_.phi, what);
  }
  if (ck.training.stage != to_string(options_.stage)) {
    throw CheckpointError(what + " is from stage '" + ck.training.stage +
                          "'; resume it with that stage, or start stage '" +
                          to_string(options_.stage) + "' from it with --init");
  }
  check_architecture(net_, ck.model, what);
  if (!code_ && !torch::equal(ck.model.at("phi"), net_->phi.to(torch::kCPU))) {
    throw CheckpointError(what +
                          " has other Phi matrices than this run although the Phi spec "
                          "is the same (did the Phi implementation change?); finetune with --init");
  }
  if (ck.optimizer.empty() && ck.training.step > 0) {
    throw CheckpointError(what +
                          " holds no optimizer state (best.ckpt keeps the model only); "
                          "resume from last.ckpt, or finetune from it with --init");
  }
  load_net_state(net_, ck.model, what);
  load_adam_state(*optimizer_, *net_, without_code(ck.optimizer), what);
  if (code_) {
    load_code_state(code_, ck.model, what, /*strict=*/true);
    load_adam_state(*code_optimizer_, *code_, code_part(ck.optimizer), what);
    fixed_code_ = torch::Tensor();
  }
  state_ = ck.training;
  if (state_.rng_state.defined()) {
    auto gen = at::detail::getDefaultCPUGenerator();
    std::lock_guard<std::mutex> lock(gen.mutex());
    gen.set_state(state_.rng_state);
  }
  last_written_ = path;
}

std::vector<std::string> Trainer::init_code_from(const std::string& path) {
  LFNET_CHECK_AS(ConfigError, static_cast<bool>(code_),
                 "a code's start from another model needs a code (set_code)");
  const std::string what = "checkpoint " + path;
  auto ck = load_checkpoint(path);
  auto copied = start_code_from(ck.model, what, /*strict=*/true);
  state_.origin["code"] = {{"checkpoint", path}, {"phi", ck.phi}};
  return copied;
}

std::vector<std::string> Trainer::start_code_from(const TensorMap& model, const std::string& what,
                                                  bool strict) {
  auto copied = load_code_state(code_, model, what, strict);
  code_optimizer_ = make_code_adam(code_, options_, code_options_);
  fixed_code_ = torch::Tensor();
  sync_code_phi();
  return copied;
}

InitReport warm_start_net(nn::LightFieldNetImpl& net, const TensorMap& model,
                          const nn::WarmStartSource& from, const std::string& prefix,
                          const std::string& what) {
  const auto& arch = net.architecture();
  InitReport report;
  torch::NoGradGuard no_grad;
  for (auto& p : net.named_parameters()) {
    const std::string& name = p.key();
    if (name.rfind(prefix, 0) != 0) continue;
    auto it = model.find(name);
    if (it == model.end()) {
      report.reinitialised.push_back(name);
      continue;
    }
    const auto& src = it->second;
    switch (arch.warm_start(net, name, src, p.value(), from)) {
      case nn::WarmStart::kCopied:
        report.copied.push_back(name);
        break;
      case nn::WarmStart::kMapped:
        report.mapped.push_back(name);
        break;
      case nn::WarmStart::kWidened:
        report.widened.push_back(name);
        break;
      case nn::WarmStart::kReinitialised:
        report.reinitialised.push_back(name);
        break;
      case nn::WarmStart::kMismatch: {
        std::ostringstream m;
        m << what << ": " << name << " is " << src.sizes() << " there but " << p.value().sizes()
          << " here; finetuning needs the same architecture apart from the autoencoder's "
             "first layer";
        throw CheckpointError(m.str());
      }
    }
  }
  for (const auto& name : arch.finish_warm_start(net, from)) {
    auto& re = report.reinitialised;
    re.erase(std::remove(re.begin(), re.end(), name), re.end());
    report.deepened.push_back(name);
  }
  return report;
}

InitReport Trainer::init_from(const std::string& path, const std::string& prefix) {
  const std::string what = "checkpoint " + path;
  auto ck = load_checkpoint(path);
  const auto old_phi = ck.model.count("phi") ? ck.model.at("phi") : torch::Tensor();
  nn::WarmStartSource from;
  from.network = ck.network;
  from.phi = old_phi;
  from.phi_changed = ck.phi != run_.phi || !old_phi.defined() ||
                     old_phi.sizes() != net_->phi.sizes() ||
                     !torch::equal(old_phi, net_->phi.to(torch::kCPU));
  auto report = warm_start_net(*net_, ck.model, from, prefix, what);
  if (code_) {
    // A model that learned a code of this family and shape hands it on (the code's own Adam
    // starts afresh, like the net's).
    for (auto& name : start_code_from(ck.model, what, /*strict=*/false)) {
      report.copied.push_back(std::move(name));
    }
  }
  if (report.copied.empty() && report.mapped.empty() && report.widened.empty()) {
    throw CheckpointError(what + " shares no parameters" +
                          (prefix.empty() ? "" : " named " + prefix + "*") + " with this network");
  }
  optimizer_ = make_adam(net_, options_);
  auto origin = state_.origin;
  state_ = TrainingState{};
  state_.stage = to_string(options_.stage);
  state_.origin = origin;
  state_.origin[prefix.empty() ? "all" : prefix.substr(0, prefix.size() - 1)] = {
      {"checkpoint", path},
      {"phi", ck.phi},
      {"stage", ck.training.stage},
      {"epoch", ck.training.epoch},
      {"report", report.to_json()}};
  last_written_.clear();
  return report;
}

InitReport Trainer::init_branches(const std::string& ae_path, const std::string& cnn_path) {
  LFNET_CHECK_AS(ConfigError, net_->options().has_ae() && net_->options().has_cnn(),
                 "init_branches needs the two-branch net (branches 'net')");
  auto report = init_from(ae_path, "ae.");
  auto cnn = init_from(cnn_path, "cnn.");
  for (auto* list : {&report.copied, &report.mapped, &report.reinitialised}) {
    list->erase(std::remove_if(list->begin(), list->end(),
                               [](const std::string& n) { return n.rfind("cnn.", 0) == 0; }),
                list->end());
  }
  report.copied.insert(report.copied.end(), cnn.copied.begin(), cnn.copied.end());
  report.mapped.insert(report.mapped.end(), cnn.mapped.begin(), cnn.mapped.end());
  report.reinitialised.insert(report.reinitialised.end(), cnn.reinitialised.begin(),
                              cnn.reinitialised.end());
  return report;
}

void Trainer::check_batch(const Batch& batch, const std::string& where) const {
  const auto& o = net_->options();
  const auto& p = o.patch;
  LFNET_CHECK(batch.y.defined() && batch.y.dim() == 2 && batch.y.size(0) >= 1 &&
                  batch.y.size(1) == o.measurement_size(),
              where, ": y must be (B, ", o.measurement_size(), "), got ",
              batch.y.defined() ? batch.y.sizes() : torch::IntArrayRef{});
  LFNET_CHECK(batch.y.scalar_type() == net_->phi.scalar_type() && batch.target.defined() &&
                  batch.target.scalar_type() == net_->phi.scalar_type(),
              where, ": y and target must be ", net_->phi.scalar_type(), " like the net, got ",
              batch.y.scalar_type(), " and ",
              batch.target.defined() ? c10::toString(batch.target.scalar_type()) : "nothing");
  const std::vector<int64_t> shape{batch.y.size(0), o.colours(), p.rows, p.cols, p.height, p.width};
  LFNET_CHECK(batch.target.defined() && batch.target.sizes() == torch::IntArrayRef(shape), where,
              ": target must be ", torch::IntArrayRef(shape), ", got ",
              batch.target.defined() ? batch.target.sizes() : torch::IntArrayRef{});
}

bool Trainer::weights_finite() const {
  for (const auto& p : net_->parameters()) {
    if (!all_finite(p)) return false;
  }
  if (code_) {
    for (const auto& p : code_->parameters()) {
      if (!all_finite(p)) return false;
    }
  }
  return true;
}

void Trainer::fail_nonfinite(const std::string& what, const Batch& batch, int64_t epoch,
                             int64_t index, double lr) const {
  std::ostringstream m;
  m << "training stopped at epoch " << epoch + 1 << ", batch " << index + 1 << " (step "
    << state_.step + 1 << "): " << what << ". ";
  if (!all_finite(batch.y)) {
    m << "The batch's measurements y contain NaN or inf: check the data source. ";
  } else if (!all_finite(batch.target)) {
    m << "The batch's target patches contain NaN or inf: check the data source. ";
  } else {
    m << "The batch is finite, so training diverged: lower the learning rate (now " << lr
      << ") or set clip_grad_norm. ";
  }
  if (last_written_.empty()) {
    m << "No checkpoint was written by this run.";
  } else {
    m << "The last good checkpoint is " << last_written_ << " (epoch " << state_.epoch
      << "); resume from it.";
  }
  throw NumericalError(m.str());
}

Evaluation Trainer::evaluate(BatchSource& source) {
  torch::NoGradGuard no_grad;
  net_->eval();
  double loss_sum = 0, squared = 0;
  int64_t patches = 0, elements = 0;
  const auto& batches = source.validation();
  const int64_t world = comm_->world_size(), rank = comm_->rank();
  for (size_t j = 0; j < batches.size(); ++j) {
    if (static_cast<int64_t>(j) % world != rank) continue;  // another rank's share
    const Batch batch = to_device(batches[j], device_);
    check_batch(batch, "validation batch");
    // A learned code measures the patches again, with the same noise every epoch.
    auto pred = code_ ? joint_forward(net_, code_weights(), batch, code_validation_seed(j))
                      : net_->forward(batch.y, batch.phase, batch.noise);
    loss_sum +=
        loss_(pred, batch.target, batch.noise).item<double>() * static_cast<double>(batch.size());
    squared += (pred.clamp(0, 1) - batch.target).to(torch::kFloat64).square().sum().item<double>();
    patches += batch.size();
    elements += batch.target.numel();
  }
  net_->train();
  if (world > 1) {
    auto sums = torch::tensor(
        {loss_sum, squared, static_cast<double>(patches), static_cast<double>(elements)},
        torch::kFloat64);
    comm_->all_reduce_sum(sums);
    loss_sum = sums[0].item<double>();
    squared = sums[1].item<double>();
    patches = static_cast<int64_t>(sums[2].item<double>());
    elements = static_cast<int64_t>(sums[3].item<double>());
  }
  LFNET_CHECK(patches > 0, "the batch source has no validation patches");
  Evaluation e;
  e.patches = patches;
  e.loss = loss_sum / static_cast<double>(patches);
  const double mse = squared / static_cast<double>(elements);
  e.psnr_db = mse > 0 ? 10 * std::log10(1.0 / mse) : INFINITY;
  return e;
}

Trainer::StepOutcome Trainer::compute_gradients(const Batch& batch, bool distributed) {
  StepOutcome out;
  out.patches = static_cast<double>(batch.size());
  if (code_) {
    // The code's weights stay in the graph unless they are fixed.
    const auto weights = fixed_code_.defined() ? fixed_code_
                         : straight_through_   ? code_->straight_through_weights()
                                               : code_->weights();
    auto loss = loss_(joint_forward(net_, weights, batch, code_noise_seed(state_.step)),
                      batch.target, batch.noise);
    out.loss = loss.item<double>();
    if (std::isfinite(out.loss)) loss.backward();
  } else if (!distributed) {
    auto loss = loss_(net_->forward(batch.y, batch.phase, batch.noise), batch.target, batch.noise);
    out.loss = loss.item<double>();
    if (std::isfinite(out.loss)) loss.backward();
  } else {
    // The loss is a mean over the batch: each rank backpropagates its patches' sum, the sums
    // are added over the ranks and divided by the global batch.
    double local_sum = 0;
    if (batch.size() > 0) {
      auto loss =
          loss_(net_->forward(batch.y, batch.phase, batch.noise), batch.target, batch.noise) *
          out.patches;
      local_sum = loss.item<double>();
      if (std::isfinite(local_sum)) loss.backward();
    }
    auto totals = torch::tensor({local_sum, out.patches}, torch::kFloat64);
    const Stopwatch clock;
    comm_->all_reduce_sum(totals);
    communication_s_ += clock.seconds();
    out.patches = totals[1].item<double>();
    out.loss = totals[0].item<double>() / out.patches;
    average_gradients(out.patches);
  }
  if (!std::isfinite(out.loss)) {
    out.problem = "the loss is " + format_double(out.loss);
    return out;
  }
  const double norm = options_.clip_grad_norm > 0 ? torch::nn::utils::clip_grad_norm_(
                                                        net_->parameters(), options_.clip_grad_norm)
                                                  : gradient_norm(*net_);
  if (!std::isfinite(norm)) out.problem = "the gradient norm is " + format_double(norm);
  if (code_ && !fixed_code_.defined() && out.problem.empty()) {
    const double code_norm = gradient_norm(*code_);
    if (!std::isfinite(code_norm)) {
      out.problem = "the code's gradient norm is " + format_double(code_norm);
    }
  }
  return out;
}

bool Trainer::agree_to_stop(bool stop) {
  if (comm_->world_size() == 1) return stop;
  auto votes = torch::tensor({stop ? int64_t{1} : int64_t{0}}, torch::kInt64);
  comm_->all_reduce_sum(votes);
  return votes.item<int64_t>() > 0;
}

void Trainer::save_checkpoints(const EpochRecord& record) {
  if (options_.out_dir.empty()) return;
  std::filesystem::create_directories(options_.out_dir);
  const auto ck = checkpoint();
  save_checkpoint(ck, last_checkpoint_path(options_.out_dir));
  last_written_ = last_checkpoint_path(options_.out_dir);
  if (record.best) {
    // best.ckpt is the model to use or finetune, which starts a fresh optimizer: without the
    // Adam moments it is a third of the size. Resuming reads last.ckpt.
    auto model_only = ck;
    model_only.optimizer.clear();
    save_checkpoint(model_only, best_checkpoint_path(options_.out_dir));
  }
}

std::vector<EpochRecord> Trainer::fit(BatchSource& source, const TrainerHooks& hooks) {
  std::vector<EpochRecord> records;
  const bool skip = options_.on_nonfinite == OnNonFinite::kSkip;
  const bool distributed = comm_->world_size() > 1;
  const bool lead = comm_->rank() == 0;  // the rank that writes checkpoints and shows progress
  LFNET_CHECK_AS(ConfigError, !(code_ && distributed),
                 "a learned code trains in one process, not data-parallel");
  if (distributed) {
    source.set_shard(comm_->rank(), comm_->world_size());
    synchronise();
  }
  for (int64_t epoch = state_.epoch; epoch < options_.epochs; ++epoch) {
    Stopwatch clock;
    communication_s_ = 0;
    source.start_epoch(epoch, options_.batch_size);
    prepare_code(epoch, source);
    const int64_t batches = source.train_batches_per_epoch();
    LFNET_CHECK(batches > 0, "the batch source has no training batches");
    std::optional<ProgressBar> bar;
    if (options_.progress && lead) {
      bar.emplace("epoch " + std::to_string(epoch + 1) + "/" + std::to_string(options_.epochs),
                  batches, "batches");
    }
    net_->train();
    double loss_sum = 0, lr = options_.lr;
    int64_t seen = 0, skipped = 0;
    for (int64_t i = 0; i < batches; ++i) {
      Batch batch = to_device(source.next_train(), device_);
      // With several ranks a last batch smaller than the world leaves some ranks nothing.
      if (!distributed || batch.size() > 0) {
        check_batch(batch, "training batch " + std::to_string(i + 1) + " of epoch " +
                               std::to_string(epoch + 1));
      }
      lr = hooks.schedule ? hooks.schedule(epoch, i, batches)
                          : learning_rate(options_, epoch, i, batches);
      apply_lr(lr);
      optimizer_->zero_grad();
      if (code_optimizer_) code_optimizer_->zero_grad();
      auto step = compute_gradients(batch, distributed);
      if (!step.problem.empty()) {
        // A bad batch can be dropped; weights that are no longer finite cannot be saved.
        if (skip && skipped < options_.max_skipped_batches && weights_finite()) {
          ++skipped;
          optimizer_->zero_grad();
          if (bar) bar->advance();
          continue;
        }
        if (skip && skipped >= options_.max_skipped_batches) {
          step.problem += " (and " + std::to_string(skipped) + " batches were skipped already)";
        }
        fail_nonfinite(step.problem, batch, epoch, i, lr);
      }
      optimizer_->step();
      if (code_ && !fixed_code_.defined()) code_optimizer_->step();
      ++state_.step;
      loss_sum += step.loss * step.patches;
      seen += static_cast<int64_t>(step.patches);
      if (bar) {
        bar->set_note("loss " + format_double(loss_sum / static_cast<double>(seen)));
        bar->advance();
      }
      if (hooks.on_step) hooks.on_step({epoch + 1, i, state_.step, step.loss, lr});
    }
    const double train_seconds = clock.seconds();
    if (bar) bar->finish();
    if (!weights_finite()) {
      fail_nonfinite("the weights are no longer finite", Batch{}, epoch, batches - 1, lr);
    }
    sync_code_phi();  // validation and checkpoints see the net with the code it has now
    const auto eval = hooks.validate ? hooks.validate(*this, source) : evaluate(source);
    if (!std::isfinite(eval.loss)) {
      fail_nonfinite("the validation loss is " + format_double(eval.loss), Batch{}, epoch,
                     batches - 1, lr);
    }
    EpochRecord r;
    r.epoch = epoch + 1;
    r.step = state_.step;
    r.lr = lr;
    r.train_loss = seen > 0 ? loss_sum / static_cast<double>(seen) : NAN;
    r.val_loss = eval.loss;
    r.val_psnr_db = eval.psnr_db;
    r.patches_per_s = train_seconds > 0 ? static_cast<double>(seen) / train_seconds : 0;
    r.communication_s = communication_s_;
    r.skipped_batches = skipped;
    r.best = eval.psnr_db > state_.best_metric;
    if (r.best) {
      state_.best_metric = eval.psnr_db;
      state_.best_epoch = r.epoch;
    }
    state_.epoch = epoch + 1;
    r.seconds = clock.seconds();
    state_.history.push_back(r.to_json());
    if (lead) {
      if (hooks.save) {
        hooks.save(*this, r);
      } else {
        save_checkpoints(r);
      }
    }
    records.push_back(r);
    if (hooks.on_epoch) hooks.on_epoch(r);
    if (agree_to_stop(hooks.stop_requested && hooks.stop_requested())) break;
  }
  return records;
}

}  // namespace lfnet::train
