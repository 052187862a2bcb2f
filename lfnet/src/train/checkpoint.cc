#include "lfnet/train/checkpoint.h"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <torch/torch.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <vector>

#include "lfnet/core/error.h"
#include "lfnet/core/hash.h"
#include "lfnet/core/json.h"
#include "lfnet/core/output.h"

namespace lfnet::train {

namespace {

constexpr char kMagic[8] = {'L', 'F', 'N', 'E', 'T', 'C', 'K', 'P'};
constexpr char kEndMagic[8] = {'L', 'F', 'N', 'E', 'T', 'E', 'N', 'D'};
constexpr size_t kPrefixSize = 8 + 4 + 8;   // magic, version, header length
constexpr size_t kTrailerSize = 8 + 8 + 8;  // payload length, checksum, end magic
constexpr size_t kAlignment = 64;
// Float tensors at least this large are stored sparse when that halves their size.
constexpr int64_t kSparseMinNumel = 1024;

template <typename T>
void put(std::string& out, T value) {
  out.append(reinterpret_cast<const char*>(&value), sizeof(T));
}

template <typename T>
T get_at(const std::string& in, size_t offset) {
  T value;
  std::memcpy(&value, in.data() + offset, sizeof(T));
  return value;
}

std::string dtype_name(torch::ScalarType t) {
  switch (t) {
    case torch::kFloat32:
      return "float32";
    case torch::kFloat64:
      return "float64";
    case torch::kInt64:
      return "int64";
    case torch::kInt32:
      return "int32";
    case torch::kUInt8:
      return "uint8";
    default:
      break;
  }
  throw Error(std::string("checkpoint: cannot store tensors of type ") + c10::toString(t));
}

torch::ScalarType dtype_of(const std::string& name) {
  if (name == "float32") return torch::kFloat32;
  if (name == "float64") return torch::kFloat64;
  if (name == "int64") return torch::kInt64;
  if (name == "int32") return torch::kInt32;
  if (name == "uint8") return torch::kUInt8;
  throw CheckpointError("unknown tensor type '" + name + "'");
}

void append_bytes(std::string& payload, const torch::Tensor& t, nlohmann::json& record,
                  const std::string& key) {
  while (payload.size() % kAlignment) payload.push_back('\0');
  record[key + "offset"] = payload.size();
  record[key + "nbytes"] = t.nbytes();
  payload.append(static_cast<const char*>(t.data_ptr()), t.nbytes());
}

// Appends `t` to the payload and returns its header record.
nlohmann::json encode(const std::string& name, const torch::Tensor& tensor, std::string& payload) {
  auto t = tensor.detach().to(torch::kCPU).contiguous();
  nlohmann::json record = {
      {"name", name}, {"dtype", dtype_name(t.scalar_type())}, {"shape", t.sizes().vec()}};
  const bool is_float = t.scalar_type() == torch::kFloat32 || t.scalar_type() == torch::kFloat64;
  if (is_float && t.numel() >= kSparseMinNumel) {
    // Non-zero by bit pattern, so -0.0 survives the round trip.
    auto bits = t.view(t.scalar_type() == torch::kFloat32 ? torch::kInt32 : torch::kInt64);
    auto index = bits.reshape({-1}).nonzero().reshape({-1});
    const bool narrow = t.numel() < (int64_t{1} << 31);
    const int64_t sparse_bytes = index.numel() * ((narrow ? 4 : 8) + t.element_size());
    if (2 * sparse_bytes <= static_cast<int64_t>(t.nbytes())) {
      record["encoding"] = "sparse";
      record["nnz"] = index.numel();
      auto values = t.reshape({-1}).index_select(0, index).contiguous();
      auto stored_index = (narrow ? index.to(torch::kInt32) : index).contiguous();
      record["index_dtype"] = narrow ? "int32" : "int64";
      append_bytes(payload, stored_index, record, "index_");
      append_bytes(payload, values, record, "");
      return record;
    }
  }
  record["encoding"] = "dense";
  append_bytes(payload, t, record, "");
  return record;
}

torch::Tensor read_array(const std::string& file, size_t payload_begin, size_t payload_size,
                         const nlohmann::json& record, const std::string& key,
                         torch::ScalarType dtype, int64_t numel) {
  const auto offset = record.at(key + "offset").get<size_t>();
  const auto nbytes = record.at(key + "nbytes").get<size_t>();
  const size_t element = c10::elementSize(dtype);
  if (offset > payload_size || nbytes > payload_size - offset ||
      nbytes != static_cast<size_t>(numel) * element) {
    throw CheckpointError("tensor '" + record.at("name").get<std::string>() +
                          "' lies outside the payload or has the wrong size");
  }
  auto t = torch::empty({numel}, dtype);
  std::memcpy(t.data_ptr(), file.data() + payload_begin + offset, nbytes);
  return t;
}

torch::Tensor decode(const std::string& file, size_t payload_begin, size_t payload_size,
                     const nlohmann::json& record) {
  const auto dtype = dtype_of(record.at("dtype").get<std::string>());
  const auto shape = record.at("shape").get<std::vector<int64_t>>();
  int64_t numel = 1;
  for (auto s : shape) {
    if (s < 0) throw CheckpointError("negative tensor size");
    numel *= s;
  }
  const auto encoding = record.at("encoding").get<std::string>();
  if (encoding == "dense") {
    return read_array(file, payload_begin, payload_size, record, "", dtype, numel).view(shape);
  }
  if (encoding != "sparse") throw CheckpointError("unknown tensor encoding '" + encoding + "'");
  const auto nnz = record.at("nnz").get<int64_t>();
  auto index = read_array(file, payload_begin, payload_size, record, "index_",
                          dtype_of(record.at("index_dtype").get<std::string>()), nnz)
                   .to(torch::kInt64);
  auto values = read_array(file, payload_begin, payload_size, record, "", dtype, nnz);
  if (nnz > 0 && (index.min().item<int64_t>() < 0 || index.max().item<int64_t>() >= numel)) {
    throw CheckpointError("tensor '" + record.at("name").get<std::string>() +
                          "' has sparse indices out of range");
  }
  auto t = torch::zeros({numel}, dtype);
  t.index_copy_(0, index, values);
  return t.view(shape);
}

std::string shape_text(torch::IntArrayRef sizes) {
  std::ostringstream out;
  out << sizes;
  return out.str();
}

}  // namespace

// ---- training state ------------------------------------------------------------------------

nlohmann::json TrainingState::to_json() const {
  return {{"stage", stage},
          {"epoch", epoch},
          {"step", step},
          {"best_metric", finite_or_null(best_metric)},
          {"best_epoch", best_epoch},
          {"history", history},
          {"origin", origin},
          {"code", code}};
}

TrainingState TrainingState::from_json(const nlohmann::json& j) {
  TrainingState s;
  s.stage = j.at("stage").get<std::string>();
  s.epoch = j.at("epoch").get<int64_t>();
  s.step = j.at("step").get<int64_t>();
  s.best_metric = number_or(j.at("best_metric"), -std::numeric_limits<double>::infinity());
  s.best_epoch = j.at("best_epoch").get<int64_t>();
  s.history = j.at("history");
  s.origin = j.value("origin", nlohmann::json::object());
  s.code = j.value("code", nlohmann::json::object());
  return s;
}

// ---- file ----------------------------------------------------------------------------------

void save_checkpoint(const Checkpoint& checkpoint, const std::string& path) {
  std::string payload;
  nlohmann::json records = nlohmann::json::array();
  for (const auto& [name, t] : checkpoint.model)
    records.push_back(encode("model/" + name, t, payload));
  for (const auto& [name, t] : checkpoint.optimizer) {
    records.push_back(encode("optimizer/" + name, t, payload));
  }
  if (checkpoint.training.rng_state.defined()) {
    records.push_back(encode("training/rng_state", checkpoint.training.rng_state, payload));
  }
  const nlohmann::json header = {{"format_version", checkpoint.format_version},
                                 {"config", checkpoint.config},
                                 {"network", checkpoint.network},
                                 {"phi", checkpoint.phi},
                                 {"command_line", checkpoint.command_line},
                                 {"optimizer_options", checkpoint.optimizer_options},
                                 {"training", checkpoint.training.to_json()},
                                 {"tensors", records}};
  const std::string header_text = header.dump();
  std::string file;
  file.reserve(kPrefixSize + header_text.size() + payload.size() + kTrailerSize);
  file.append(kMagic, 8);
  put<uint32_t>(file, checkpoint.format_version);
  put<uint64_t>(file, header_text.size());
  file += header_text;
  file += payload;
  put<uint64_t>(file, payload.size());
  put<uint64_t>(file, fnv1a(file.data(), file.size()));
  file.append(kEndMagic, 8);

  write_bytes_file(path, file, /*durable=*/true);
}

Checkpoint load_checkpoint(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError("cannot read checkpoint " + path + ": no such file or not readable");
  std::string file((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string where = "checkpoint " + path;
  if (file.size() < 8 || std::memcmp(file.data(), kMagic, 8) != 0) {
    throw CheckpointError(where + " is not an lfnet checkpoint (it does not start with LFNETCKP)");
  }
  if (file.size() < kPrefixSize) throw CheckpointError(where + " is truncated");
  const auto version = get_at<uint32_t>(file, 8);
  if (version != kCheckpointFormatVersion) {
    throw CheckpointError(where + " has format version " + std::to_string(version) +
                          "; this lfnet reads version " + std::to_string(kCheckpointFormatVersion) +
                          (version > kCheckpointFormatVersion ? " (it was written by a newer lfnet)"
                                                              : " (re-train or convert it)"));
  }
  const auto header_size = get_at<uint64_t>(file, 12);
  if (file.size() < kPrefixSize + kTrailerSize || header_size > file.size() ||
      std::memcmp(file.data() + file.size() - 8, kEndMagic, 8) != 0) {
    throw CheckpointError(where + " is truncated (" + std::to_string(file.size()) +
                          " bytes, no end marker): it was cut off while being copied or written");
  }
  const size_t trailer = file.size() - kTrailerSize;
  const auto payload_size = get_at<uint64_t>(file, trailer);
  if (kPrefixSize + header_size + payload_size != trailer) {
    throw CheckpointError(where + " is truncated or corrupted (its sections do not add up)");
  }
  if (get_at<uint64_t>(file, trailer + 8) != fnv1a(file.data(), trailer + 8)) {
    throw CheckpointError(where + " is corrupted (checksum mismatch)");
  }
  Checkpoint ck;
  try {
    const auto header = nlohmann::json::parse(file.substr(kPrefixSize, header_size));
    ck.format_version = header.at("format_version").get<uint32_t>();
    ck.config = header.at("config");
    ck.network = header.at("network");
    ck.phi = header.at("phi");
    ck.command_line = header.at("command_line").get<std::string>();
    ck.optimizer_options = header.at("optimizer_options");
    ck.training = TrainingState::from_json(header.at("training"));
    const size_t payload_begin = kPrefixSize + header_size;
    for (const auto& record : header.at("tensors")) {
      const auto name = record.at("name").get<std::string>();
      auto t = decode(file, payload_begin, payload_size, record);
      if (name.rfind("model/", 0) == 0) {
        ck.model[name.substr(6)] = t;
      } else if (name.rfind("optimizer/", 0) == 0) {
        ck.optimizer[name.substr(10)] = t;
      } else if (name == "training/rng_state") {
        ck.training.rng_state = t;
      } else {
        throw CheckpointError("unexpected tensor '" + name + "'");
      }
    }
  } catch (const CheckpointError& e) {
    throw CheckpointError(where + " is corrupted: " + e.what());
  } catch (const nlohmann::json::exception& e) {
    throw CheckpointError(where + " has a malformed header: " + e.what());
  }
  return ck;
}

// ---- models --------------------------------------------------------------------------------

TensorMap module_state(const torch::nn::Module& module) {
  TensorMap state;
  for (const auto& p : module.named_parameters()) {
    state[p.key()] = p.value().detach().to(torch::kCPU).contiguous().clone();
  }
  for (const auto& b : module.named_buffers()) {
    state[b.key()] = b.value().detach().to(torch::kCPU).contiguous().clone();
  }
  return state;
}

void check_architecture(const nn::LightFieldNet& net, const TensorMap& state,
                        const std::string& what) {
  std::vector<std::string> problems;
  std::set<std::string> mine;
  auto compare = [&](const std::string& name, const torch::Tensor& t) {
    mine.insert(name);
    auto it = state.find(name);
    if (it == state.end()) {
      problems.push_back("it lacks " + name);
      return;
    }
    auto want = t.sizes().vec(), got = it->second.sizes().vec();
    // The Phi buffers may hold another number of phases.
    if (!want.empty() && want.size() == got.size()) {
      for (size_t axis : net->architecture().phase_axes(name, want.size())) want[axis] = got[axis];
    }
    if (want != got) {
      problems.push_back(name + " is " + shape_text(it->second.sizes()) + " there but " +
                         shape_text(t.sizes()) + " here");
    }
  };
  for (const auto& p : net->named_parameters()) compare(p.key(), p.value());
  for (const auto& b : net->named_buffers()) compare(b.key(), b.value());
  for (const auto& [name, t] : state) {
    if (name.rfind(kCodePrefix, 0) == 0) continue;  // a learned code's, not the net's
    if (!mine.count(name)) problems.push_back("it has " + name + ", which this net lacks");
  }
  if (problems.empty()) return;
  std::string message = what + " holds another architecture than this network: ";
  for (size_t i = 0; i < problems.size() && i < 6; ++i) message += (i ? "; " : "") + problems[i];
  if (problems.size() > 6) message += "; and " + std::to_string(problems.size() - 6) + " more";
  throw CheckpointError(message);
}

void load_net_state(nn::LightFieldNet& net, const TensorMap& state, const std::string& what) {
  check_architecture(net, state, what);
  torch::NoGradGuard no_grad;
  net->set_phi(state.at("phi"));
  for (auto& p : net->named_parameters()) p.value().copy_(state.at(p.key()));
  for (auto& b : net->named_buffers()) b.value().copy_(state.at(b.key()));
}

std::vector<std::string> load_code_state(nn::LearnedPhi& code, const TensorMap& state,
                                         const std::string& what, bool strict) {
  std::vector<std::string> copied;
  torch::NoGradGuard no_grad;
  for (auto& p : code->named_parameters()) {
    const std::string name = kCodePrefix + p.key();
    const auto it = state.find(name);
    if (it == state.end() || it->second.sizes() != p.value().sizes()) {
      if (!strict) continue;
      throw CheckpointError(what + ": its learned " + code->options().family + " code lacks " +
                            p.key() + " or holds it in another shape");
    }
    p.value().copy_(it->second);
    copied.push_back(name);
  }
  return copied;
}

nn::LightFieldNet build_net(const Checkpoint& checkpoint, const std::string& what) {
  nn::NetworkOptions options;
  try {
    options = nn::NetworkOptions::from_file_json(checkpoint.network, "$.network");
  } catch (const ConfigError& e) {
    throw CheckpointError(what + " has invalid network options: " + e.what());
  }
  nn::LightFieldNet net(options);
  load_net_state(net, checkpoint.model, what);
  return net;
}

void check_phi(const Checkpoint& checkpoint, const nlohmann::json& phi_spec,
               const std::string& what) {
  if (checkpoint.phi == phi_spec) return;
  throw CheckpointError(what + " was trained for Phi " + phi_label(checkpoint.phi) +
                        " but the measurements come from Phi " + phi_label(phi_spec) +
                        ": they differ in " +
                        json_differences(checkpoint.phi, phi_spec, "model", "measurements") +
                        ". Simulate with the model's Phi (--phi " + what +
                        "), or finetune the model for this Phi (train --init)");
}

}  // namespace lfnet::train
