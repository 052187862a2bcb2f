#include "lfnet/core/file_backed.h"

#include <torch/torch.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#if defined(__linux__)
#include <fcntl.h>
#include <linux/magic.h>
#include <sys/mman.h>
#include <sys/statfs.h>
#include <unistd.h>
#endif

namespace lfnet {

namespace {

// The size from which tensors are file-backed by default (set_file_backed_threshold).
std::atomic<size_t> threshold{kFileBackedMinBytes};

// The live mappings: base address to length, for file_backed and page_out.
std::mutex mappings_mutex;
std::map<void*, size_t>& mappings() {
  static std::map<void*, size_t> m;
  return m;
}

#if defined(__linux__)
void unmap(void* base) {
  size_t length = 0;
  {
    const std::lock_guard<std::mutex> lock(mappings_mutex);
    auto it = mappings().find(base);
    if (it == mappings().end()) return;
    length = it->second;
    mappings().erase(it);
  }
  munmap(base, length);
}

// Folders for the file, in order: $TMPDIR, /var/tmp, /tmp; those in memory are left out.
std::vector<std::string> temporary_folders() {
  std::vector<std::string> out;
  if (const char* env = std::getenv("TMPDIR"); env != nullptr && *env != '\0') out.push_back(env);
  out.emplace_back("/var/tmp");
  out.emplace_back("/tmp");
  std::vector<std::string> on_disk;
  for (const auto& dir : out) {
    struct statfs fs {};
    if (statfs(dir.c_str(), &fs) != 0) continue;
    if (fs.f_type == TMPFS_MAGIC || fs.f_type == RAMFS_MAGIC) continue;
    on_disk.push_back(dir);
  }
  return on_disk;
}

// A shared mapping of `bytes` from a new unlinked file in `dir`, or nullptr.
void* map_temporary(const std::string& dir, size_t bytes) {
  std::string path = dir + "/lfnet-XXXXXX";
  const int fd = mkstemp(path.data());
  if (fd < 0) return nullptr;
  unlink(path.c_str());
  void* base = MAP_FAILED;
  if (posix_fallocate(fd, 0, static_cast<off_t>(bytes)) == 0) {
    base = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd, 0);
  }
  close(fd);  // the mapping keeps the file
  return base == MAP_FAILED ? nullptr : base;
}
#endif

}  // namespace

size_t file_backed_threshold() { return threshold.load(); }
void set_file_backed_threshold(size_t bytes) { threshold.store(bytes); }

torch::Tensor file_backed_empty(at::IntArrayRef sizes, at::ScalarType dtype, size_t min_bytes) {
  const auto options = torch::TensorOptions().dtype(dtype);
  int64_t count = 1;
  for (const auto s : sizes) count *= s;
  const size_t bytes = static_cast<size_t>(count) * c10::elementSize(dtype);
#if defined(__linux__)
  const char* env = std::getenv("LFNET_FILE_BACKED");  // "0": everything in memory
  const bool allowed = env == nullptr || std::string(env) != "0";
  if (allowed && bytes > 0 && bytes >= min_bytes) {
    for (const auto& dir : temporary_folders()) {
      void* base = map_temporary(dir, bytes);
      if (base == nullptr) continue;
      {
        const std::lock_guard<std::mutex> lock(mappings_mutex);
        mappings()[base] = bytes;
      }
      return torch::from_blob(
          base, sizes, [base](void*) { unmap(base); }, options);
    }
  }
#endif
  return torch::empty(sizes, options);
}

torch::Tensor file_backed_copy(const torch::Tensor& t, size_t min_bytes) {
  if (t.is_contiguous() && (file_backed(t) || t.nbytes() < min_bytes)) return t;
  auto out = file_backed_empty(t.sizes(), t.scalar_type(), min_bytes);
  out.copy_(t);
  return out;
}

bool file_backed(const torch::Tensor& t) {
  if (!t.defined() || !t.has_storage()) return false;
  // The storage's own start: a mapping is one storage.
  const std::lock_guard<std::mutex> lock(mappings_mutex);
  return mappings().count(t.storage().data()) != 0;
}

void page_out(const torch::Tensor& t) {
#if defined(__linux__)
  if (!t.defined() || !t.has_storage() || t.numel() == 0) return;
  // The bytes t spans, from its first element to its last.
  int64_t last = 0;
  for (int64_t d = 0; d < t.dim(); ++d) last += (t.size(d) - 1) * t.stride(d);
  auto* first = static_cast<char*>(t.data_ptr());
  char* end = first + (last + 1) * static_cast<int64_t>(t.element_size());
  {
    const std::lock_guard<std::mutex> lock(mappings_mutex);
    auto it = mappings().upper_bound(first);
    if (it == mappings().begin()) return;
    --it;
    auto* base = static_cast<char*>(it->first);
    if (first >= base + it->second) return;  // in no mapping
  }
  // Whole pages only: the pages at either end may hold bytes of other rows or views. A shared
  // file mapping keeps its contents in the file: the pages are only unmapped here.
  const auto page = static_cast<uintptr_t>(sysconf(_SC_PAGESIZE));
  char* a = first + (page - reinterpret_cast<uintptr_t>(first) % page) % page;
  char* b = end - reinterpret_cast<uintptr_t>(end) % page;
  if (b > a) madvise(a, static_cast<size_t>(b - a), MADV_DONTNEED);
#else
  (void)t;
#endif
}

}  // namespace lfnet
