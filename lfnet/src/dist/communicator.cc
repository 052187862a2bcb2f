#include "lfnet/dist/communicator.h"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <mutex>
#include <sstream>
#include <thread>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#ifdef LFNET_HAVE_C10D
#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>
#endif

namespace lfnet::dist {

std::string DistOptions::host() const {
  const auto colon = master.rfind(':');
  return colon == std::string::npos ? master : master.substr(0, colon);
}

int DistOptions::port() const {
  const auto colon = master.rfind(':');
  if (colon == std::string::npos) return -1;
  try {
    size_t used = 0;
    const int p = std::stoi(master.substr(colon + 1), &used);
    return used == master.size() - colon - 1 ? p : -1;
  } catch (const std::exception&) {
    return -1;
  }
}

void DistOptions::validate() const {
  if (world_size < 1)
    throw ConfigError("world_size: must be >= 1, got " + std::to_string(world_size));
  if (rank < 0 || rank >= world_size) {
    throw ConfigError("rank: must lie in [0, " + std::to_string(world_size - 1) + "], got " +
                      std::to_string(rank));
  }
  if (world_size > 1) {
    if (host().empty() || port() < 1 || port() > 65535) {
      throw ConfigError("master: '" + master + "' is not HOST:PORT with a port in 1..65535");
    }
    if (!(timeout_s > 0)) throw ConfigError("timeout_s: must be positive");
  }
}

std::pair<int64_t, int64_t> shard_range(int64_t n, int64_t rank, int64_t world) {
  LFNET_CHECK(world >= 1 && rank >= 0 && rank < world && n >= 0, "shard_range(", n, ", ", rank,
              ", ", world, "): bad arguments");
  const int64_t base = n / world, extra = n % world;
  const int64_t begin = rank * base + std::min(rank, extra);
  return {begin, begin + base + (rank < extra ? 1 : 0)};
}

int free_loopback_port() {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  LFNET_CHECK_AS(IoError, fd >= 0, "cannot open a socket: ", std::strerror(errno));
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;  // the kernel picks a free one
  socklen_t len = sizeof(addr);
  const bool ok = ::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) == 0 &&
                  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) == 0;
  const int error = errno;
  ::close(fd);
  LFNET_CHECK_AS(IoError, ok, "cannot find a free loopback port: ", std::strerror(error));
  return ntohs(addr.sin_port);
}

#ifdef LFNET_HAVE_C10D

bool available() { return true; }

namespace {

bool is_loopback(const std::string& host) {
  return host == "localhost" || host.rfind("127.", 0) == 0 || host == "::1";
}

std::string first_line(const std::string& s) {
  auto line = s.substr(0, s.find('\n'));
  return line.empty() ? s : line;
}

std::string rank_list(const std::vector<int64_t>& ranks) {
  std::string s = ranks.size() == 1 ? "rank " : "ranks ";
  for (size_t i = 0; i < ranks.size(); ++i) s += (i ? ", " : "") + std::to_string(ranks[i]);
  return s;
}

std::string alive_key(int64_t rank) { return "lfnet/alive/" + std::to_string(rank); }
std::string joined_key(int64_t rank) { return "lfnet/joined/" + std::to_string(rank); }

// Every rank's sign of life, through the job's store (docs/distributed.md, "Faults between
// hosts"): a thread of its own adds 1 to this rank's counter every second and reads the
// others'. A rank whose counter stops (its process ended, its host or link went down) is
// named as lost, and so is rank 0 when the store it holds stops answering. The thread has its
// own connection to the store, so a collective blocked on a lost peer does not block it.
class Heartbeat {
 public:
  Heartbeat(const std::string& host, int port, int64_t rank, int64_t world)
      : state_(std::make_shared<State>()) {
    c10d::TCPStoreOptions so;
    so.port = static_cast<uint16_t>(port);
    so.isServer = false;
    so.waitWorkers = false;
    so.timeout = kStoreTimeout;
    auto& s = *state_;
    s.rank = rank;
    // Rank 0 holds the store: it reaches it through loopback even when its link is down.
    s.store = c10::make_intrusive<c10d::TCPStore>(rank == 0 ? "127.0.0.1" : host, so);
    const auto now = Clock::now();
    s.last_seen.assign(static_cast<size_t>(world), now);
    s.counts.assign(static_cast<size_t>(world), -1);
    s.store_seen = now;
    // The thread shares the state: when a store call hangs on a dead link, the thread is left
    // behind at destruction (below), and the state lives on with it.
    thread_ = std::thread([state = state_] { loop(*state); });
  }
  ~Heartbeat() {
    std::unique_lock<std::mutex> lock(state_->mutex);
    state_->stop = true;
    state_->wake.notify_all();
    // A store call on a link that went down waits for TCP, minutes: not for it.
    if (state_->wake.wait_for(lock, kStoreTimeout, [this] { return state_->finished; })) {
      lock.unlock();
      thread_.join();
    } else {
      thread_.detach();
    }
  }
  Heartbeat(const Heartbeat&) = delete;
  Heartbeat& operator=(const Heartbeat&) = delete;

  // What is lost after `silence` without a sign of it: "" when nothing is.
  std::string lost(std::chrono::milliseconds silence) const {
    auto& s = *state_;
    std::lock_guard<std::mutex> lock(s.mutex);
    const auto now = Clock::now();
    std::vector<int64_t> silent;
    for (size_t r = 0; r < s.last_seen.size(); ++r) {
      if (static_cast<int64_t>(r) != s.rank && now - s.last_seen[r] > silence) {
        silent.push_back(static_cast<int64_t>(r));
      }
    }
    // While the store cannot be reached, nothing is known of the other ranks: the lost one is
    // the store's. Rank 0 holds the store, so a silent rank 0 is named as its holder too: a
    // rank 0 killed a moment ago may be seen silent before this thread's next call to its store
    // fails.
    const bool store_unreached = s.rank != 0 && now - s.store_seen > 2 * kPeriod;
    const bool rank0_silent = !silent.empty() && silent.front() == 0;
    if (s.rank != 0 &&
        (rank0_silent || (store_unreached && (!silent.empty() || now - s.store_seen > silence)))) {
      return "rank 0, which holds the job's store, stopped answering (its process ended, or "
             "its host or the network to it is down)";
    }
    if (silent.empty()) return "";
    return rank_list(silent) + " stopped answering (its process ended, or its host or the " +
           "network to it is down)";
  }

 private:
  using Clock = std::chrono::steady_clock;
  static constexpr std::chrono::milliseconds kStoreTimeout{3000};
  static constexpr std::chrono::milliseconds kPeriod{1000};

  struct State {
    int64_t rank = 0;
    c10::intrusive_ptr<c10d::TCPStore> store;  // a connection of the heartbeat's own
    std::mutex mutex;
    std::condition_variable wake;
    bool stop = false, finished = false;
    Clock::time_point store_seen;
    std::vector<Clock::time_point> last_seen;
    std::vector<int64_t> counts;
  };

  static void loop(State& s) {
    std::unique_lock<std::mutex> lock(s.mutex);
    while (!s.stop) {
      lock.unlock();
      std::vector<int64_t> counts(s.counts.size(), -1);
      bool reached = false;
      try {
        for (size_t r = 0; r < counts.size(); ++r) {
          const auto rank = static_cast<int64_t>(r);
          counts[r] = s.store->add(alive_key(rank), rank == s.rank ? 1 : 0);
        }
        reached = true;
      } catch (const std::exception&) {
        // The store is silent or gone: `lost` says so once the silence lasts.
      }
      lock.lock();
      const auto now = Clock::now();
      if (reached) {
        s.store_seen = now;
        for (size_t r = 0; r < counts.size(); ++r) {
          if (counts[r] != s.counts[r]) s.last_seen[r] = now;
          s.counts[r] = counts[r];
        }
      }
      s.wake.wait_for(lock, kPeriod, [&s] { return s.stop; });
    }
    s.finished = true;
    s.wake.notify_all();
  }

  std::shared_ptr<State> state_;
  std::thread thread_;
};

// A c10d Gloo process group; every failure becomes a CommunicationError naming this rank and,
// where the heartbeat tells, the lost one.
class GlooCommunicator : public Communicator {
 public:
  explicit GlooCommunicator(const DistOptions& o)
      : rank_(o.rank),
        world_(o.world_size),
        timeout_(static_cast<int64_t>(o.timeout_s * 1000)),
        silence_(std::max<int64_t>(std::min<int64_t>(timeout_.count(), kLongestSilence.count()),
                                   kShortestSilence.count())) {
    where_ = "rank " + std::to_string(rank_) + " of " + std::to_string(world_);
    const std::string waited = " within " + seconds_text(o.timeout_s);
    try {
      c10d::TCPStoreOptions so;
      so.port = static_cast<uint16_t>(o.port());
      so.isServer = rank_ == 0;
      so.numWorkers = static_cast<size_t>(world_);
      so.waitWorkers = false;  // the joined/ keys below say which rank is missing
      so.timeout = timeout_;
      store_ = c10::make_intrusive<c10d::TCPStore>(o.host(), so);
    } catch (const std::exception& e) {
      throw CommunicationError(
          where_ + ": " +
          (rank_ == 0 ? "cannot hold the job's store at " + o.master + ": " + first_line(e.what())
                      : "the job's store at " + o.master + " (rank 0) did not answer" + waited +
                            " (is rank 0 started, and can this host reach " + o.host() +
                            "?): " + first_line(e.what())));
    }
    // Every rank says it joined; each waits for all, and names the ranks that did not.
    std::vector<std::string> keys;
    keys.reserve(static_cast<size_t>(world_));
    for (int64_t r = 0; r < world_; ++r) keys.push_back(joined_key(r));
    try {
      store_->set(joined_key(rank_), std::vector<uint8_t>{1});
      store_->wait(keys, timeout_);
    } catch (const std::exception& e) {
      std::vector<int64_t> missing;
      try {
        for (int64_t r = 0; r < world_; ++r) {
          if (!store_->check({joined_key(r)})) missing.push_back(r);
        }
      } catch (const std::exception&) {
        throw CommunicationError(where_ + ": the job's store at " + o.master +
                                 " (rank 0) stopped answering while the ranks joined");
      }
      throw CommunicationError(
          where_ + ": " +
          (missing.empty() ? "the ranks did not all join" + waited + ": " + first_line(e.what())
                           : rank_list(missing) + " did not join" + waited) +
          " (is every rank started, with the same --world-size " + std::to_string(world_) +
          " and --master " + o.master + "?)");
    }
    try {
      auto pg_options = c10d::ProcessGroupGloo::Options::create(timeout_);
      std::string interface = o.interface;
      if (interface.empty()) {
        if (const char* env = std::getenv("GLOO_SOCKET_IFNAME")) interface = env;
      }
      if (!interface.empty()) {
        pg_options->devices.push_back(c10d::ProcessGroupGloo::createDeviceForInterface(interface));
      } else if (is_loopback(o.host())) {
        pg_options->devices.push_back(c10d::ProcessGroupGloo::createDeviceForHostname("127.0.0.1"));
      } else {
        pg_options->devices.push_back(c10d::ProcessGroupGloo::createDefaultDevice());
      }
      // One thread suffices: the tensors are reduced one collective at a time.
      pg_options->threads = 1;
      pg_ = c10::make_intrusive<c10d::ProcessGroupGloo>(store_, static_cast<int>(rank_),
                                                        static_cast<int>(world_), pg_options);
      heartbeat_ = std::make_unique<Heartbeat>(o.host(), o.port(), rank_, world_);
    } catch (const std::exception& e) {
      throw CommunicationError(
          where_ + ": the ranks joined at " + o.master + " but could not connect to each other" +
          waited +
          " (--dist-interface, or a firewall between the hosts?): " + first_line(e.what()));
    }
  }

  ~GlooCommunicator() override {
    heartbeat_.reset();
    if (abandoned_) {
      // A collective given up on a lost rank may still wait inside Gloo until its timeout:
      // the process group is left to the exit, which does not wait for it.
      (void)pg_.release();
      (void)store_.release();
    }
  }

  int64_t rank() const override { return rank_; }
  int64_t world_size() const override { return world_; }

  void all_reduce_sum(torch::Tensor& t) override {
    std::vector<at::Tensor> tensors{contiguous(t, "all_reduce_sum")};
    run("all-reduce", [&] { return pg_->allreduce(tensors); });
    if (!tensors[0].is_same(t)) t.copy_(tensors[0]);
  }

  void broadcast(torch::Tensor& t, int64_t root) override {
    std::vector<at::Tensor> tensors{contiguous(t, "broadcast")};
    c10d::BroadcastOptions bo;
    bo.rootRank = root;
    run("broadcast", [&] { return pg_->broadcast(tensors, bo); });
    if (!tensors[0].is_same(t)) t.copy_(tensors[0]);
  }

  std::vector<std::string> all_gather(const std::string& bytes) override {
    // Gloo gathers equal sizes: first the lengths, then the payloads padded to the longest.
    auto lengths = gather_tensor(torch::tensor({static_cast<int64_t>(bytes.size())}));
    int64_t longest = 0;
    for (const auto& l : lengths) longest = std::max(longest, l.item<int64_t>());
    auto mine = torch::zeros({std::max<int64_t>(longest, 1)}, torch::kUInt8);
    std::copy(bytes.begin(), bytes.end(), mine.data_ptr<uint8_t>());
    auto payloads = gather_tensor(mine);
    std::vector<std::string> out;
    for (size_t r = 0; r < payloads.size(); ++r) {
      const auto* p = payloads[r].data_ptr<uint8_t>();
      out.emplace_back(reinterpret_cast<const char*>(p),
                       static_cast<size_t>(lengths[r].item<int64_t>()));
    }
    return out;
  }

  void barrier() override {
    run("barrier", [&] { return pg_->barrier(); });
  }

 private:
  // A rank silent this long is lost, even when the collective's timeout is longer.
  static constexpr std::chrono::milliseconds kLongestSilence{30000};
  // ... and only one silent this long: a busy machine may delay a beat by a second or two.
  static constexpr std::chrono::milliseconds kShortestSilence{5000};
  static constexpr std::chrono::milliseconds kSlice{250};

  static std::string seconds_text(double s) {
    std::ostringstream text;
    text << s << " s";
    return text.str();
  }

  torch::Tensor contiguous(const torch::Tensor& t, const char* what) const {
    LFNET_CHECK(t.defined() && t.device().is_cpu(), where_, ": ", what, " needs a CPU tensor");
    return t.is_contiguous() ? t : t.contiguous();
  }

  std::vector<torch::Tensor> gather_tensor(const torch::Tensor& t) {
    std::vector<std::vector<at::Tensor>> outputs(1);
    outputs[0].reserve(static_cast<size_t>(world_));
    for (int64_t r = 0; r < world_; ++r) outputs[0].push_back(torch::empty_like(t));
    std::vector<at::Tensor> inputs{t};
    run("all-gather", [&] { return pg_->allgather(outputs, inputs); });
    return outputs[0];
  }

  // Waits for the collective in slices; between them the heartbeat says whether a rank is lost,
  // so a peer that vanished without closing its sockets is named after `silence_`, not after
  // Gloo's timeout. Gloo's own failures (a closed socket, its timeout) are named the same way.
  template <typename Fn>
  void run(const char* what, Fn&& start) {
    c10::intrusive_ptr<c10d::Work> work;
    try {
      work = start();
    } catch (const std::exception& e) {
      fail(what, first_line(e.what()));
    }
    while (true) {
      try {
        work->wait(kSlice);
        return;
      } catch (const std::exception& e) {
        if (work->isCompleted()) fail(what, first_line(e.what()));
      }
      if (heartbeat_) {
        const auto lost = heartbeat_->lost(silence_);
        if (!lost.empty()) {
          abandoned_ = true;
          throw CommunicationError(where_ + ": " + what + " failed: " + lost);
        }
      }
    }
  }

  [[noreturn]] void fail(const char* what, const std::string& reason) {
    abandoned_ = true;
    // A rank that just died closed its sockets a moment ago: its heartbeat is seen to stop
    // within a few seconds (a stalled rank's goes on).
    std::string lost;
    for (int i = 0; heartbeat_ && lost.empty() && i <= 20; ++i) {
      if (i > 0) std::this_thread::sleep_for(std::chrono::milliseconds(250));
      lost = heartbeat_->lost(std::chrono::milliseconds(2500));
    }
    throw CommunicationError(
        where_ + ": " + what +
        " failed: " + (lost.empty() ? "another rank failed or stalled (see its output)" : lost) +
        " [" + reason + "]");
  }

  int64_t rank_, world_;
  std::chrono::milliseconds timeout_, silence_;
  std::string where_;
  bool abandoned_ = false;
  c10::intrusive_ptr<c10d::TCPStore> store_;
  c10::intrusive_ptr<c10d::ProcessGroupGloo> pg_;
  std::unique_ptr<Heartbeat> heartbeat_;
};

}  // namespace

std::shared_ptr<Communicator> connect(const DistOptions& options) {
  options.validate();
  if (options.world_size == 1) return std::make_shared<LocalCommunicator>();
  // Writing to the socket of a rank that died raises SIGPIPE, which would kill this process
  // silently; ignored, the write fails and Gloo throws, which becomes a CommunicationError.
  std::signal(SIGPIPE, SIG_IGN);
  return std::make_shared<GlooCommunicator>(options);
}

#else

bool available() { return false; }

std::shared_ptr<Communicator> connect(const DistOptions& options) {
  options.validate();
  if (options.world_size == 1) return std::make_shared<LocalCommunicator>();
  throw ConfigError(
      "this lfnet was built without distributed training: LibTorch's c10d headers "
      "(torch/csrc/distributed/c10d/ProcessGroupGloo.hpp) or Gloo's (libgloo-dev) were missing "
      "at build time; install them and rebuild (docs/distributed.md)");
}

#endif

}  // namespace lfnet::dist
