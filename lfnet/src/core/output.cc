#include "lfnet/core/output.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstring>
#include <fstream>

#include "lfnet/core/error.h"

namespace fs = std::filesystem;

namespace lfnet {

namespace {

fs::path normalised(const fs::path& p) {
  std::error_code ec;
  fs::path out = fs::weakly_canonical(fs::absolute(p), ec);
  if (ec) out = fs::absolute(p).lexically_normal();
  if (out.filename().empty()) out = out.parent_path();  // "dir/" names "dir"
  return out;
}

// True when `inner` is `outer` or lies inside it.
bool within(const fs::path& inner, const fs::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i) {
    if (i == inner.end() || *i != *o) return false;
  }
  return true;
}

fs::path folder_of(const fs::path& target) {
  return target.has_parent_path() ? target.parent_path() : fs::path(".");
}

void sync_path(const fs::path& p, int flags) {
  const int fd = ::open(p.c_str(), flags | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

}  // namespace

fs::path temporary_path(const fs::path& target) {
  const fs::path name = target.filename();
  return folder_of(target) / ("." + name.stem().string() + ".tmp" + std::to_string(::getpid()) +
                              name.extension().string());
}

void remove_stale_temporaries(const fs::path& target) {
  // Temporaries are `.<stem>.tmp<pid><extension>` (temporary_path) and, for a folder being
  // replaced, `.<name>.tmp<pid>.old`.
  const fs::path name = target.filename();
  const std::string prefixes[] = {"." + name.stem().string() + ".tmp",
                                  "." + name.string() + ".tmp"};
  const std::string endings[] = {name.extension().string(), ".old", ""};
  std::error_code ec;
  for (fs::directory_iterator it(folder_of(target), ec), end; !ec && it != end; it.increment(ec)) {
    const std::string entry = it->path().filename().string();
    pid_t pid = 0;
    for (const auto& prefix : prefixes) {
      if (entry.rfind(prefix, 0) != 0) continue;
      const size_t digits_end = entry.find_first_not_of("0123456789", prefix.size());
      const std::string digits = entry.substr(prefix.size(), digits_end - prefix.size());
      const std::string rest = digits_end == std::string::npos ? "" : entry.substr(digits_end);
      if (digits.empty() || digits.size() > 9) continue;
      for (const auto& ending : endings) {
        if (rest == ending) pid = static_cast<pid_t>(std::stol(digits));
      }
    }
    if (pid <= 0 || pid == ::getpid()) continue;
    if (::kill(pid, 0) != 0 && errno == ESRCH) {
      std::error_code ignored;
      fs::remove_all(it->path(), ignored);
    }
  }
}

void write_file_atomically(const std::string& target,
                           const std::function<void(const std::string&)>& write, bool durable) {
  const fs::path path(target);
  const std::string tmp = temporary_path(path).string();
  std::error_code ec;
  try {
    write(tmp);
    if (durable) sync_path(tmp, O_RDONLY);
  } catch (...) {
    fs::remove(tmp, ec);
    throw;
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    throw IoError("cannot write " + target + ": " + ec.message());
  }
  remove_stale_temporaries(path);
  if (durable) sync_path(folder_of(path), O_RDONLY | O_DIRECTORY);
}

void write_text_file(const std::string& target, const std::string& text) {
  write_file_atomically(target, [&](const std::string& tmp) {
    std::ofstream out(tmp, std::ios::binary);
    LFNET_CHECK_AS(IoError, out, "cannot write ", target);
    out << text;
    out.flush();
    LFNET_CHECK_AS(IoError, out.good(), "cannot write ", target);
  });
}

void check_output_apart(const std::string& output, const std::vector<std::string>& inputs,
                        const std::string& option) {
  const fs::path out = normalised(output);
  for (const auto& input : inputs) {
    if (input.empty()) continue;
    const fs::path in = normalised(input);
    LFNET_CHECK_AS(ConfigError, !within(out, in) && !within(in, out), option, " ", output,
                   within(out, in) ? (out == in ? " is the input " : " lies inside the input ")
                                   : " contains the input ",
                   input, ": choose an output apart from what the command reads");
  }
}

OutputLock::OutputLock(const std::string& output, const std::string& option) {
  fs::path target = normalised(output);
  std::error_code ec;
  fs::create_directories(target.parent_path(), ec);
  LFNET_CHECK_AS(IoError, !ec, "cannot create the folder of ", option, " ", output, ": ",
                 ec.message());
  path_ = (target.parent_path() / ("." + target.filename().string() + ".lock")).string();
  // A lock file another writer unlinks while we wait is no longer the lock: retry on the new one.
  for (int attempt = 0; attempt < 8; ++attempt) {
    fd_ = ::open(path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    LFNET_CHECK_AS(IoError, fd_ >= 0, "cannot create the lock ", path_, ": ", std::strerror(errno));
    if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
      const int why = errno;
      ::close(fd_);
      fd_ = -1;
      LFNET_CHECK_AS(ConfigError, why != EWOULDBLOCK, option, " ", output,
                     " is being written by another lfnet process: wait for it or choose "
                     "another output");
      throw IoError("cannot lock " + path_ + ": " + std::strerror(why));
    }
    struct stat held {
    }, named{};
    if (::fstat(fd_, &held) == 0 && ::stat(path_.c_str(), &named) == 0 &&
        held.st_ino == named.st_ino && held.st_dev == named.st_dev) {
      return;
    }
    ::close(fd_);
    fd_ = -1;
  }
  throw IoError("cannot lock " + path_ + ": it keeps being replaced");
}

OutputLock::~OutputLock() {
  if (fd_ < 0) return;
  ::unlink(path_.c_str());
  ::close(fd_);
}

void check_output_folder(const std::string& out, const OutputFolderPolicy& policy) {
  LFNET_CHECK_AS(ConfigError, !out.empty(), policy.option, " is empty: name an output folder");
  check_output_apart(out, policy.inputs, policy.option);
  const fs::path target = normalised(out);
  std::error_code ec;
  if (fs::exists(fs::symlink_status(target, ec))) {
    LFNET_CHECK_AS(ConfigError, fs::is_directory(target, ec), policy.option, " ", out,
                   " exists and is not a folder");
    LFNET_CHECK_AS(ConfigError, policy.force || fs::is_empty(target, ec), policy.option, " ", out,
                   " exists and is not empty: choose another folder or pass --force to "
                   "replace it");
  }
}

void check_output_file(const std::string& out, const OutputFolderPolicy& policy) {
  LFNET_CHECK_AS(ConfigError, !out.empty(), policy.option, " is empty: name an output file");
  check_output_apart(out, policy.inputs, policy.option);
  std::error_code ec;
  const auto status = fs::status(out, ec);
  if (!fs::exists(status)) return;
  LFNET_CHECK_AS(ConfigError, !fs::is_directory(status), policy.option, " ", out,
                 " is a folder: name a file");
  LFNET_CHECK_AS(ConfigError, policy.force, policy.option, " ", out,
                 " exists: choose another file or pass --force to replace it");
}

std::vector<std::string> split_paths(const std::string& list) {
  std::vector<std::string> out;
  size_t start = 0;
  while (start <= list.size()) {
    const size_t comma = list.find(',', start);
    const std::string item =
        list.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    if (!item.empty()) out.push_back(item);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

void write_folder(const std::string& out, const OutputFolderPolicy& policy,
                  const std::function<void(const std::string&)>& write) {
  const fs::path target = normalised(out);
  check_output_folder(out, policy);
  OutputLock lock(out, policy.option);
  check_output_folder(out, policy);  // again, now that no other writer can change it
  std::error_code ec;
  const bool exists = fs::exists(fs::symlink_status(target, ec));
  remove_stale_temporaries(target);
  const fs::path tmp = temporary_path(target);
  fs::remove_all(tmp, ec);
  fs::create_directories(tmp, ec);
  LFNET_CHECK_AS(IoError, !ec, "cannot create the output folder ", out, ": ", ec.message());
  try {
    write(tmp.string());
  } catch (...) {
    fs::remove_all(tmp, ec);
    throw;
  }
  // The old folder is renamed aside (a temporary of this writer, so a crash here leaves
  // something the next writer removes), the new one takes its place, then the old one goes.
  fs::path old;
  if (exists) {
    old = target.parent_path() /
          ("." + target.filename().string() + ".tmp" + std::to_string(::getpid()) + ".old");
    fs::rename(target, old, ec);
    if (ec) {
      std::error_code ignored;
      fs::remove_all(tmp, ignored);
      throw IoError("cannot replace " + out + ": " + ec.message());
    }
  }
  fs::rename(tmp, target, ec);
  if (ec) {
    std::error_code ignored;
    if (exists) fs::rename(old, target, ignored);
    fs::remove_all(tmp, ignored);
    throw IoError("cannot move the result into " + out + ": " + ec.message());
  }
  if (exists) fs::remove_all(old, ec);
}

namespace {
OutputFolderPolicy with_force(OutputFolderPolicy policy, bool force) {
  policy.force = force;
  return policy;
}
}  // namespace

RunFolder::RunFolder(const std::string& dir, const OutputFolderPolicy& policy, bool resume)
    : dir_(dir), lock_(dir, policy.option) {
  check_output_folder(dir, with_force(policy, policy.force || resume));
  const fs::path target = normalised(dir);
  std::error_code ec;
  remove_stale_temporaries(target);
  const bool exists = fs::exists(target, ec);
  if (exists && !resume && !fs::is_empty(target, ec)) {
    aside_ = target.parent_path() /
             ("." + target.filename().string() + ".tmp" + std::to_string(::getpid()) + ".old");
    fs::rename(target, aside_, ec);
    LFNET_CHECK_AS(IoError, !ec, "cannot move the old ", dir, " aside: ", ec.message());
  }
  created_ = !exists || !aside_.empty();
  fs::create_directories(target, ec);
  if (ec) {
    std::error_code ignored;
    if (!aside_.empty()) fs::rename(aside_, target, ignored);
    throw IoError("cannot create " + dir + ": " + ec.message());
  }
}

void RunFolder::commit() {
  if (committed_) return;
  committed_ = true;
  std::error_code ec;
  if (!aside_.empty()) fs::remove_all(aside_, ec);
}

RunFolder::~RunFolder() {
  if (committed_) return;
  std::error_code ec;
  if (created_) fs::remove_all(normalised(dir_), ec);
  if (!aside_.empty()) fs::rename(aside_, normalised(dir_), ec);
}

}  // namespace lfnet
