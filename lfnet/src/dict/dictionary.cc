#include "lfnet/dict/dictionary.h"

#include <torch/serialize.h>
#include <torch/torch.h>
#include <unistd.h>

#include <filesystem>
#include <sstream>

#include "lfnet/core/error.h"
#include "lfnet/core/output.h"
#include "lfnet/core/zip_check.h"

namespace lfnet::dict {

namespace {
constexpr const char* kFormatName = "lfnet-dictionary";
constexpr const char* kMetaKey = "lfnet_dictionary_meta";
constexpr const char* kAtomsKey = "atoms";
}  // namespace

void Dictionary::validate() const {
  LFNET_CHECK(atoms.defined() && atoms.dim() == 2 && atoms.size(1) >= 1,
              "dictionary: atoms must be a (d, K) matrix, got ",
              atoms.defined() ? atoms.sizes() : c10::IntArrayRef{});
  LFNET_CHECK(atoms.scalar_type() == torch::kFloat32, "dictionary: atoms must be float32");
  int64_t d = 1;
  for (int64_t s : patch_shape) {
    LFNET_CHECK(s >= 1, "dictionary: patch shape entries must be >= 1");
    d *= s;
  }
  LFNET_CHECK(atoms.size(0) == d, "dictionary: atoms have ", atoms.size(0),
              " entries but the patch shape ", patch_shape[0], "x", patch_shape[1], "x",
              patch_shape[2], "x", patch_shape[3], " has ", d);
  LFNET_CHECK_AS(NumericalError, torch::isfinite(atoms).all().item<bool>(),
                 "dictionary: atoms have NaN or inf entries");
}

void save_dictionary(const Dictionary& dictionary, const std::string& path) {
  dictionary.validate();
  nlohmann::json meta = {{"format", kFormatName},
                         {"version", kDictionaryFormatVersion},
                         {"patch_shape", dictionary.patch_shape},
                         {"atoms", dictionary.size()},
                         {"training", dictionary.training}};
  torch::serialize::OutputArchive archive;
  archive.write(kAtomsKey, dictionary.atoms.contiguous());
  archive.write(kMetaKey, c10::IValue(meta.dump()));
  // Archived in memory, then written by lfnet (LibTorch's file writer aborts on a full disk).
  std::ostringstream bytes;
  try {
    archive.save_to(bytes);
  } catch (const c10::Error& e) {
    throw IoError("cannot write dictionary " + path + ": " + e.what_without_backtrace());
  }
  write_bytes_file(path, bytes.str());
}

Dictionary load_dictionary(const std::string& path) {
  if (!std::filesystem::is_regular_file(path)) {
    throw IoError("cannot read dictionary " + path + ": no such file");
  }
  check_zip_integrity(path, "dictionary " + path);
  torch::serialize::InputArchive archive;
  try {
    archive.load_from(path);
  } catch (const c10::Error& e) {
    throw CheckpointError("dictionary " + path +
                          " is truncated or not a LibTorch archive: " + e.what_without_backtrace());
  } catch (const std::exception& e) {
    // Damaged archive code fails in the TorchScript compiler, over several lines.
    const std::string what = e.what();
    throw CheckpointError("dictionary " + path + " is damaged: " + what.substr(0, what.find('\n')));
  }
  c10::IValue meta_value;
  bool has_meta = false;
  try {
    has_meta = archive.try_read(kMetaKey, meta_value) && meta_value.isString();
  } catch (const c10::Error&) {
    has_meta = false;
  }
  if (!has_meta) {
    throw CheckpointError("dictionary " + path +
                          " is a LibTorch archive but not an lfnet dictionary (no " + kMetaKey +
                          " record)");
  }
  nlohmann::json meta;
  try {
    meta = nlohmann::json::parse(meta_value.toStringRef());
  } catch (const nlohmann::json::exception& e) {
    throw CheckpointError("dictionary " + path + ": unreadable metadata: " + e.what());
  }
  if (!meta.is_object() || meta.value("format", std::string()) != kFormatName) {
    throw CheckpointError("dictionary " + path + " is not an lfnet dictionary (format \"" +
                          (meta.is_object() ? meta.value("format", std::string("?")) : "?") +
                          "\")");
  }
  const int64_t version = meta.value("version", int64_t{-1});
  if (version != kDictionaryFormatVersion) {
    throw CheckpointError("dictionary " + path + " has format version " + std::to_string(version) +
                          "; this lfnet reads version " + std::to_string(kDictionaryFormatVersion));
  }
  Dictionary dict;
  try {
    dict.patch_shape = meta.at("patch_shape").get<std::array<int64_t, 4>>();
    dict.training = meta.value("training", nlohmann::json::object());
    archive.read(kAtomsKey, dict.atoms);
  } catch (const std::exception& e) {
    throw CheckpointError("dictionary " + path + " is incomplete: " + e.what());
  }
  try {
    dict.validate();
  } catch (const Error& e) {
    throw CheckpointError("dictionary " + path + " is inconsistent: " + e.what());
  }
  if (meta.value("atoms", int64_t{-1}) != dict.size()) {
    throw CheckpointError("dictionary " + path + ": the metadata names " +
                          std::to_string(meta.value("atoms", int64_t{-1})) +
                          " atoms but the file holds " + std::to_string(dict.size()));
  }
  return dict;
}

}  // namespace lfnet::dict
