#include "lfnet/dist/communicator.h"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <cstring>

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

// A c10d Gloo process group; every failure becomes a CommunicationError naming the rank.
class GlooCommunicator : public Communicator {
 public:
  explicit GlooCommunicator(const DistOptions& o) : rank_(o.rank), world_(o.world_size) {
    const auto timeout = std::chrono::milliseconds(static_cast<int64_t>(o.timeout_s * 1000));
    where_ = "rank " + std::to_string(rank_) + " of " + std::to_string(world_);
    try {
      c10d::TCPStoreOptions so;
      so.port = static_cast<uint16_t>(o.port());
      so.isServer = rank_ == 0;
      so.numWorkers = static_cast<size_t>(world_);
      so.waitWorkers = true;
      so.timeout = timeout;
      store_ = c10::make_intrusive<c10d::TCPStore>(o.host(), so);
      auto pg_options = c10d::ProcessGroupGloo::Options::create(timeout);
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
    } catch (const std::exception& e) {
      throw CommunicationError(where_ + ": the rendezvous at " + o.master + " failed within " +
                               std::to_string(o.timeout_s) +
                               " s (did every rank start, with the same --world-size and "
                               "--master, and can this host reach it?): " +
                               first_line(e.what()));
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
  static std::string first_line(const std::string& s) {
    auto line = s.substr(0, s.find('\n'));
    return line.empty() ? s : line;
  }

  torch::Tensor contiguous(const torch::Tensor& t, const char* what) const {
    LFNET_CHECK(t.defined() && t.device().is_cpu(), where_, ": ", what, " needs a CPU tensor");
    return t.is_contiguous() ? t : t.contiguous();
  }

  std::vector<torch::Tensor> gather_tensor(const torch::Tensor& t) {
    std::vector<std::vector<at::Tensor>> outputs(1);
    for (int64_t r = 0; r < world_; ++r) outputs[0].push_back(torch::empty_like(t));
    std::vector<at::Tensor> inputs{t};
    run("all-gather", [&] { return pg_->allgather(outputs, inputs); });
    return outputs[0];
  }

  template <typename Fn>
  void run(const char* what, Fn&& start) {
    try {
      auto work = start();
      work->wait();
    } catch (const std::exception& e) {
      throw CommunicationError(where_ + ": " + what +
                               " failed; another rank has died, stalled or failed (see its "
                               "output): " +
                               first_line(e.what()));
    }
  }

  int64_t rank_, world_;
  std::string where_;
  c10::intrusive_ptr<c10d::Store> store_;
  c10::intrusive_ptr<c10d::ProcessGroupGloo> pg_;
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
