#include "lfnet/core/output.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstring>
#include <fstream>

#include "lfnet/core/error.h"
#include "lfnet/core/text.h"

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

bool remove_stale_temporaries(const fs::path& target) {
  // Temporaries are `.<stem>.tmp<pid><extension>` (temporary_path); a folder being replaced
  // (write_folder) is moved to `.<name>.tmp<pid>.old`, a run replaced by --force (RunFolder) to
  // `.<name>.tmp<pid>.replaced`, and either goes through `.<name>.tmp<pid>.discard` on its way
  // out.
  const fs::path name = target.filename();
  const std::string prefixes[] = {"." + name.stem().string() + ".tmp",
                                  "." + name.string() + ".tmp"};
  const std::string endings[] = {name.extension().string(), ".old", ".replaced", ".discard", ""};
  std::error_code ec;
  std::vector<std::pair<fs::path, std::string>> dead;  // entry, ending
  for (fs::directory_iterator it(folder_of(target), ec), end; !ec && it != end; it.increment(ec)) {
    const std::string entry = it->path().filename().string();
    pid_t pid = 0;
    std::string kind;
    for (const auto& prefix : prefixes) {
      if (entry.rfind(prefix, 0) != 0) continue;
      const size_t digits_end = entry.find_first_not_of("0123456789", prefix.size());
      const std::string digits = entry.substr(prefix.size(), digits_end - prefix.size());
      const std::string rest = digits_end == std::string::npos ? "" : entry.substr(digits_end);
      if (digits.empty() || digits.size() > 9) continue;
      for (const auto& ending : endings) {
        if (rest == ending) {
          pid = static_cast<pid_t>(std::stol(digits));
          kind = ending;
        }
      }
    }
    if (pid <= 0 || pid == ::getpid()) continue;
    if (::kill(pid, 0) != 0 && errno == ESRCH) dead.emplace_back(it->path(), kind);
  }
  bool restored = false;
  for (const auto& [path, kind] : dead) {
    std::error_code ignored;
    const bool target_exists = fs::exists(fs::symlink_status(target, ignored));
    // A run replaced by --force whose new run never reached its first checkpoint comes back (the
    // new run's folder goes); a folder swap cut between its two renames gets its old folder back.
    const bool put_back = kind == ".replaced" || (kind == ".old" && !target_exists);
    if (put_back && fs::is_directory(path, ignored)) {
      if (target_exists) {
        const fs::path discard = temporary_path(target).string() + ".discard";
        fs::rename(target, discard, ignored);
        fs::remove_all(discard, ignored);
      }
      fs::rename(path, target, ignored);
      restored = restored || !ignored;
      if (!ignored) continue;
    }
    fs::remove_all(path, ignored);
  }
  return restored;
}

namespace {

// ": No space left on device" when the file system holding `p` has no block left: libraries
// that write images or archives report a failed write without the system's reason.
std::string full_disk_reason(const fs::path& p, int error) {
  if (error == ENOSPC || error == EDQUOT || error == EFBIG)
    return std::string(": ") + std::strerror(error);
  struct statvfs fs_info {};
  if (::statvfs(folder_of(p).c_str(), &fs_info) == 0 && fs_info.f_bavail == 0) {
    return std::string(": ") + std::strerror(ENOSPC);
  }
  return "";
}

}  // namespace

void write_all(int fd, std::string_view data, const std::string& path) {
  size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::write(fd, data.data() + done, data.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw IoError("cannot write " + path + ": " + std::strerror(n < 0 ? errno : EIO));
    done += static_cast<size_t>(n);
  }
}

void write_file_atomically(const std::string& target,
                           const std::function<void(const std::string&)>& write, bool durable) {
  const fs::path path(target);
  const std::string tmp = temporary_path(path).string();
  std::error_code ec;
  try {
    errno = 0;
    write(tmp);
    if (durable) sync_path(tmp, O_RDONLY);
  } catch (const IoError& e) {
    // Before the temporary goes, while the space it took is still taken.
    const std::string what = replace_all(e.what(), tmp, target);
    const std::string reason =
        what.find(std::strerror(ENOSPC)) == std::string::npos ? full_disk_reason(tmp, errno) : "";
    fs::remove(tmp, ec);
    throw IoError(what + reason);
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

void write_pieces_file(const std::string& target, const std::vector<std::string_view>& pieces,
                       bool durable) {
  write_file_atomically(
      target,
      [&](const std::string& tmp) {
        const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
        if (fd < 0) throw IoError("cannot write " + target + ": " + std::strerror(errno));
        try {
          for (const auto piece : pieces) write_all(fd, piece, target);
        } catch (...) {
          ::close(fd);
          throw;
        }
        if (::close(fd) != 0) throw IoError("cannot write " + target + ": " + std::strerror(errno));
      },
      durable);
}

void write_bytes_file(const std::string& target, std::string_view bytes, bool durable) {
  write_pieces_file(target, {bytes}, durable);
}

void write_text_file(const std::string& target, const std::string& text) {
  write_bytes_file(target, text);
}

void check_regular_input(const std::string& path) {
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (ec || !fs::exists(status)) return;
  LFNET_CHECK_AS(IoError, !fs::is_directory(status), path, " is a folder, not a file");
  LFNET_CHECK_AS(IoError, fs::is_regular_file(status), path,
                 " is not a regular file (a FIFO, socket or device), which lfnet does not read");
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
  // The folders made here go again with the lock if the output never came (a failed write).
  for (fs::path p = target.parent_path(); !p.empty() && !fs::exists(p, ec); p = p.parent_path()) {
    made_ = p;
    if (p == p.parent_path()) break;
  }
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
  // Empty folders this lock made, innermost first, up to the first it made.
  std::error_code ec;
  for (fs::path p = fs::path(path_).parent_path(); !made_.empty(); p = p.parent_path()) {
    if (!fs::is_empty(p, ec) || ec || !fs::remove(p, ec)) break;
    if (p == made_) break;
  }
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
  // An empty file (one made by mktemp, say) holds nothing to lose, as an empty folder.
  LFNET_CHECK_AS(ConfigError, policy.force || fs::file_size(out, ec) == 0, policy.option, " ", out,
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
  remove_stale_temporaries(target);  // may put back a folder an interrupted swap had moved aside
  check_output_folder(out, policy);  // again, now that no other writer can change it
  std::error_code ec;
  const bool exists = fs::exists(fs::symlink_status(target, ec));
  const fs::path tmp = temporary_path(target);
  fs::remove_all(tmp, ec);
  fs::create_directories(tmp, ec);
  LFNET_CHECK_AS(IoError, !ec, "cannot create the output folder ", out, ": ", ec.message());
  try {
    write(tmp.string());
  } catch (const IoError& e) {
    fs::remove_all(tmp, ec);
    throw IoError(replace_all(e.what(), tmp.string(), target.string()));
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
  const fs::path target = normalised(dir);
  remove_stale_temporaries(target);  // first: it may put back a run an interrupted --force replaced
  check_output_folder(dir, with_force(policy, policy.force || resume));
  std::error_code ec;
  const bool exists = fs::exists(target, ec);
  if (exists && !resume && !fs::is_empty(target, ec)) {
    aside_ = target.parent_path() /
             ("." + target.filename().string() + ".tmp" + std::to_string(::getpid()) + ".replaced");
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
  if (aside_.empty()) return;
  // Renamed first, in one step: a `.replaced` folder left behind would be put back.
  std::error_code ec;
  const fs::path discard = aside_.parent_path() / (aside_.stem().string() + ".discard");
  fs::rename(aside_, discard, ec);
  fs::remove_all(ec ? aside_ : discard, ec);
}

RunFolder::~RunFolder() {
  if (committed_) return;
  std::error_code ec;
  if (created_) fs::remove_all(normalised(dir_), ec);
  if (!aside_.empty()) fs::rename(aside_, normalised(dir_), ec);
}

}  // namespace lfnet
