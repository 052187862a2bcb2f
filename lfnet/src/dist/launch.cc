#include "lfnet/dist/launch.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "lfnet/core/error.h"

namespace lfnet::dist {

namespace {

// One started rank: its process and the read ends of its stdout and stderr.
struct Child {
  pid_t pid = -1;
  int out = -1, err = -1;
  std::string out_buffer, err_buffer;
  bool running = true;
  int status = 0;
};

// Writes the complete lines of `buffer` to `stream` with the rank's prefix.
void forward_lines(std::string& buffer, FILE* stream, const std::string& prefix, bool flush_all) {
  size_t start = 0;
  for (size_t nl; (nl = buffer.find('\n', start)) != std::string::npos; start = nl + 1) {
    std::fprintf(stream, "%s%.*s\n", prefix.c_str(), static_cast<int>(nl - start),
                 buffer.data() + start);
  }
  buffer.erase(0, start);
  if (flush_all && !buffer.empty()) {
    std::fprintf(stream, "%s%s\n", prefix.c_str(), buffer.c_str());
    buffer.clear();
  }
  std::fflush(stream);
}

// Reads what is available on fd into buffer; false at end of file.
bool drain(int& fd, std::string& buffer) {
  char chunk[4096];
  const ssize_t n = ::read(fd, chunk, sizeof(chunk));
  if (n > 0) {
    buffer.append(chunk, static_cast<size_t>(n));
    return true;
  }
  if (n < 0 && (errno == EINTR || errno == EAGAIN)) return true;
  ::close(fd);
  fd = -1;
  return false;
}

std::string describe(int status) {
  if (WIFEXITED(status)) return "exited with status " + std::to_string(WEXITSTATUS(status));
  if (WIFSIGNALED(status))
    return std::string("was killed by signal ") + strsignal(WTERMSIG(status));
  return "ended";
}

Child start_rank(const std::string& program, const std::vector<std::string>& argv) {
  int out[2], err[2];
  LFNET_CHECK_AS(IoError, ::pipe(out) == 0 && ::pipe(err) == 0,
                 "cannot create a pipe: ", std::strerror(errno));
  std::vector<char*> c_argv;
  c_argv.reserve(argv.size() + 1);
  for (const auto& a : argv) c_argv.push_back(const_cast<char*>(a.c_str()));
  c_argv.push_back(nullptr);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  LFNET_CHECK_AS(IoError, pid >= 0, "cannot start a rank: ", std::strerror(errno));
  if (pid == 0) {
    // Only async-signal-safe calls between fork and exec. A rank dies with its launcher (killed
    // or not, it never outlives it to train alone).
    ::prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (::getppid() != parent) ::_exit(127);
    ::dup2(out[1], STDOUT_FILENO);
    ::dup2(err[1], STDERR_FILENO);
    ::close(out[0]);
    ::close(out[1]);
    ::close(err[0]);
    ::close(err[1]);
    ::execv(program.c_str(), c_argv.data());
    const char msg[] = "lfnet launch: cannot execute the rank's program\n";
    [[maybe_unused]] auto ignored = ::write(STDERR_FILENO, msg, sizeof(msg) - 1);
    ::_exit(127);
  }
  ::close(out[1]);
  ::close(err[1]);
  for (int fd : {out[0], err[0]}) ::fcntl(fd, F_SETFD, FD_CLOEXEC);
  Child c;
  c.pid = pid;
  c.out = out[0];
  c.err = err[0];
  return c;
}

}  // namespace

void launch_local(const LaunchOptions& a,
                  const std::function<std::vector<std::string>(int64_t rank)>& argv_of) {
  LFNET_CHECK_AS(ConfigError, a.ranks >= 1, "launch needs at least one rank");
  std::vector<Child> children;
  for (int64_t r = 0; r < a.ranks; ++r) children.push_back(start_rank(a.program, argv_of(r)));
  int failed = -1;  // the first rank that failed
  auto stop_time = std::chrono::steady_clock::time_point::max();
  int remaining = static_cast<int>(children.size());
  while (remaining > 0) {
    std::vector<pollfd> fds;
    std::vector<std::pair<size_t, bool>> which;  // (rank, is stderr)
    for (size_t r = 0; r < children.size(); ++r) {
      if (children[r].out >= 0) {
        fds.push_back({children[r].out, POLLIN, 0});
        which.emplace_back(r, false);
      }
      if (children[r].err >= 0) {
        fds.push_back({children[r].err, POLLIN, 0});
        which.emplace_back(r, true);
      }
    }
    if (!fds.empty())
      ::poll(fds.data(), fds.size(), 100);
    else
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    for (size_t i = 0; i < fds.size(); ++i) {
      if (!(fds[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
      auto& c = children[which[i].first];
      const std::string prefix = "[rank " + std::to_string(which[i].first) + "] ";
      if (which[i].second) {
        const bool open = drain(c.err, c.err_buffer);
        forward_lines(c.err_buffer, stderr, prefix, !open);
      } else {
        const bool open = drain(c.out, c.out_buffer);
        forward_lines(c.out_buffer, stdout, prefix, !open);
      }
    }
    for (size_t r = 0; r < children.size(); ++r) {
      auto& c = children[r];
      if (!c.running || ::waitpid(c.pid, &c.status, WNOHANG) != c.pid) continue;
      c.running = false;
      --remaining;
      const bool ok = WIFEXITED(c.status) && WEXITSTATUS(c.status) == 0;
      if (!ok && failed < 0) {
        failed = static_cast<int>(r);
        // One rank failing dooms the job: stop the others rather than wait for their timeout.
        for (auto& other : children) {
          if (other.running) ::kill(other.pid, SIGTERM);
        }
        stop_time = std::chrono::steady_clock::now() +
                    std::chrono::milliseconds(static_cast<int64_t>(a.grace_s * 1000));
      }
    }
    if (std::chrono::steady_clock::now() > stop_time) {
      for (auto& other : children) {
        if (other.running) ::kill(other.pid, SIGKILL);
      }
      stop_time = std::chrono::steady_clock::time_point::max();
    }
  }
  for (auto& c : children) {  // output left after the processes ended
    while (c.out >= 0 && drain(c.out, c.out_buffer)) {
    }
    while (c.err >= 0 && drain(c.err, c.err_buffer)) {
    }
  }
  for (size_t r = 0; r < children.size(); ++r) {
    const std::string prefix = "[rank " + std::to_string(r) + "] ";
    forward_lines(children[r].out_buffer, stdout, prefix, true);
    forward_lines(children[r].err_buffer, stderr, prefix, true);
  }
  if (failed >= 0) {
    throw Error("rank " + std::to_string(failed) + " of " + std::to_string(a.ranks) + " " +
                describe(children[failed].status) +
                "; the other ranks were stopped (see the [rank N] lines above)");
  }
}

}  // namespace lfnet::dist
