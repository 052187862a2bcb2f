// lfnet launch: starts the ranks of a data-parallel job on this host (docs/distributed.md).
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <spdlog/spdlog.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <thread>

#include "command.h"
#include "lfnet/core/error.h"
#include "lfnet/dist/communicator.h"

namespace lfnet::app {

namespace {

struct LaunchArgs {
  int64_t ranks = 2;
  int port = 0;  // 0: a free one
  double grace_s = 5;
  std::vector<std::string> command;
};

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

Child start_rank(const std::vector<std::string>& argv) {
  int out[2], err[2];
  LFNET_CHECK_AS(IoError, ::pipe(out) == 0 && ::pipe(err) == 0,
                 "cannot create a pipe: ", std::strerror(errno));
  std::vector<char*> c_argv;
  for (const auto& a : argv) c_argv.push_back(const_cast<char*>(a.c_str()));
  c_argv.push_back(nullptr);
  const pid_t pid = ::fork();
  LFNET_CHECK_AS(IoError, pid >= 0, "cannot start a rank: ", std::strerror(errno));
  if (pid == 0) {
    // Only async-signal-safe calls between fork and exec.
    ::dup2(out[1], STDOUT_FILENO);
    ::dup2(err[1], STDERR_FILENO);
    ::close(out[0]);
    ::close(out[1]);
    ::close(err[0]);
    ::close(err[1]);
    ::execv("/proc/self/exe", c_argv.data());
    const char msg[] = "lfnet launch: cannot execute /proc/self/exe\n";
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

void run_launch(const LaunchArgs& a, const GlobalOptions& global) {
  LFNET_CHECK_AS(ConfigError, !a.command.empty(),
                 "name the subcommand to run after --, e.g. lfnet launch -n 2 -- train "
                 "configs/quickstart.json");
  const std::string& verb = a.command.front();
  LFNET_CHECK_AS(ConfigError, verb == "train" || verb == "batch", "lfnet launch runs 'train' or ",
                 "'batch', not '", verb, "'");
  for (const auto& arg : a.command) {
    for (const char* flag : {"--world-size", "--rank", "--master"}) {
      LFNET_CHECK_AS(ConfigError, arg.rfind(flag, 0) != 0, "lfnet launch sets ", flag,
                     " itself: leave it out of the command");
    }
  }
  const int port = a.port > 0 ? a.port : dist::free_loopback_port();
  const std::string master = "127.0.0.1:" + std::to_string(port);
  // Every rank computing with every core would oversubscribe the host: share the cores.
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const int threads =
      global.threads > 0 ? global.threads : std::max(1, cores / static_cast<int>(a.ranks));
  spdlog::info("launching {} ranks of 'lfnet {}' on {} with {} thread(s) each", a.ranks, verb,
               master, threads);
  std::vector<Child> children;
  for (int64_t r = 0; r < a.ranks; ++r) {
    std::vector<std::string> argv{"lfnet", "--threads", std::to_string(threads), "--log-level",
                                  global.log_level};
    argv.insert(argv.end(), a.command.begin(), a.command.end());
    for (const auto& extra :
         {std::string("--world-size"), std::to_string(a.ranks), std::string("--rank"),
          std::to_string(r), std::string("--master"), master}) {
      argv.push_back(extra);
    }
    children.push_back(start_rank(argv));
  }
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
  spdlog::info("all {} ranks finished", a.ranks);
}

}  // namespace

void add_launch_command(CLI::App& app, const GlobalOptions& global) {
  auto* cmd = app.add_subcommand(
      "launch", "Run a data-parallel job of N local ranks: lfnet launch -n 2 -- train CONFIG.json");
  auto args = std::make_shared<LaunchArgs>();
  cmd->add_option("-n,--ranks", args->ranks, "ranks (processes) to start (default 2)")
      ->check(CLI::Range(1, 1024));
  cmd->add_option("--port", args->port, "loopback port of the rendezvous (default: a free one)")
      ->check(CLI::Range(1, 65535));
  cmd->add_option("--grace", args->grace_s,
                  "seconds the other ranks get to stop after one fails, before SIGKILL (default 5)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("command", args->command, "after --: the subcommand and its arguments")
      ->required();
  cmd->callback([args, &global] { run_launch(*args, global); });
}

}  // namespace lfnet::app
