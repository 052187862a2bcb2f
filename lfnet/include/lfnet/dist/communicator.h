// Data-parallel communication between the processes of one job (docs/distributed.md): a thin
// layer over PyTorch's own distributed engine, c10d, with Gloo as the transport and a TCPStore
// on rank 0 as the rendezvous. The header names no c10d type, so the library builds where the
// c10d headers are missing; connect() then says so at run time.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "lfnet/core/error.h"

namespace lfnet::dist {

// Another rank died, stalled past the timeout, or never joined: the job cannot go on.
class CommunicationError : public Error {
 public:
  using Error::Error;
};

// Where this process stands in the job.
struct DistOptions {
  int64_t world_size = 1;                  // processes in the job (1: no communication at all)
  int64_t rank = 0;                        // this process, 0 .. world_size - 1
  std::string master = "127.0.0.1:29500";  // HOST:PORT of rank 0, which hosts the rendezvous
  // Seconds to wait for the rendezvous and for each collective operation before giving up
  // with a CommunicationError (a dead peer usually fails sooner: its sockets close).
  double timeout_s = 300;
  // Network interface for the Gloo transport ("" : $GLOO_SOCKET_IFNAME, else loopback when
  // the master is a loopback address, else the address the host name resolves to).
  std::string interface;

  std::string host() const;  // the HOST of master
  int port() const;          // the PORT of master
  void validate() const;     // ConfigError naming the field
};

// The collective operations the trainer and the batch runner need. Every rank must call the
// same operations in the same order; a failure throws CommunicationError naming this rank.
class Communicator {
 public:
  virtual ~Communicator() = default;
  virtual int64_t rank() const = 0;
  virtual int64_t world_size() const = 0;
  // Sums `t` over all ranks, in place; every rank receives the same values.
  virtual void all_reduce_sum(torch::Tensor& t) = 0;
  // Replaces `t` on every rank by rank `root`'s (same shape and dtype everywhere).
  virtual void broadcast(torch::Tensor& t, int64_t root = 0) = 0;
  // Every rank's `bytes`, in rank order, on every rank (lengths may differ).
  virtual std::vector<std::string> all_gather(const std::string& bytes) = 0;
  // Returns once every rank has called it.
  virtual void barrier() = 0;
};

// A job of one process: every collective returns its input.
class LocalCommunicator : public Communicator {
 public:
  int64_t rank() const override { return 0; }
  int64_t world_size() const override { return 1; }
  void all_reduce_sum(torch::Tensor&) override {}
  void broadcast(torch::Tensor&, int64_t) override {}
  std::vector<std::string> all_gather(const std::string& bytes) override { return {bytes}; }
  void barrier() override {}
};

// True when lfnet was built with c10d's Gloo process group.
bool available();

// Joins the job: LocalCommunicator for world_size 1, otherwise a c10d Gloo process group that
// rendezvous at options.master (rank 0 listens there). Blocks until all ranks have joined;
// CommunicationError after timeout_s, ConfigError for bad options or a build without c10d.
// Several ranks make the process ignore SIGPIPE, so a dead peer is an error, not a silent death.
std::shared_ptr<Communicator> connect(const DistOptions& options);

// The part [begin, end) of n items that rank `rank` of `world` takes: contiguous, sizes
// differing by at most one, earlier ranks taking the larger parts.
std::pair<int64_t, int64_t> shard_range(int64_t n, int64_t rank, int64_t world);

// A TCP port on the loopback interface that was free a moment ago (for jobs on one host;
// another program may still take it before rank 0 binds it).
int free_loopback_port();

}  // namespace lfnet::dist
