// The processes of a `pisco-vk run` (docs/scaling.md): one, in the single-process build (and in the
// MPI build started without mpirun), or the ranks of MPI_COMM_WORLD in the MPI build (PISCO_WITH_MPI),
// started as `mpirun -n N pisco-vk run sim.toml`. The library knows nothing of MPI: everything MPI
// does for a run is here, behind this interface, and run.cpp is the same code for one process or many.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>

#include "pisco/error.hpp"
#include "pisco/mapmaker.hpp"

namespace pisco_cli {

// An error every process knows (Cluster::agree): printed once, by rank 0.
class AgreedError : public pisco::Error {
 public:
  using pisco::Error::Error;
};

class Cluster {
 public:
  // Starts MPI (in the MPI build) for the life of the object; the one Cluster of the program.
  Cluster(int& argc, char**& argv);
  ~Cluster();
  Cluster(const Cluster&) = delete;
  Cluster& operator=(const Cluster&) = delete;
  static Cluster& get();

  int rank() const noexcept { return rank_; }
  int size() const noexcept { return size_; }
  int node_rank() const noexcept { return node_rank_; }  // among the ranks of this node
  int node_size() const noexcept { return node_size_; }
  bool leader() const noexcept { return rank_ == 0; }
  bool parallel() const noexcept { return size_ > 1; }
  // Ends every rank at once (MPI_Abort), the last resort for an error outside the collective steps;
  // returns in a single process.
  void abort(int status);
  // Ends MPI now (every rank; the destructor does it otherwise): before a failed run's exit status,
  // so that no rank is still inside MPI when mpirun, seeing the status, stops the others.
  void finalize();

  // Collective: every process passes its error (none: nullopt). When any has one, every process
  // throws AgreedError with the message of the lowest failing rank ("rank R: ..." when parallel).
  void agree(const std::optional<std::string>& error);
  // Runs f; with several processes, an exception is kept and passed to agree() (a collective call).
  void step(const std::function<void()>& f);

  std::string broadcast(const std::string& text_of_rank0);
  void barrier();
  double max(double v);
  std::uint64_t sum(std::uint64_t v);
  double sum_of(double v);
  // Adds every process's normal equations into rank 0's map-maker, in a fixed binary tree (rank r
  // adds r + 1, r + 2, r + 4, ... in that order), so that the maps depend on nothing but the number
  // of processes; returns the bytes this process sent.
  std::uint64_t reduce(pisco::BinnedMapmaker& mapper);
  // Replaces `values` on every process by their sum over the processes, added in the same fixed tree
  // and broadcast from rank 0, so that every process has the same bits (the deconvolving map-maker's
  // maps: every process runs the same conjugate-gradient steps).
  void sum_in_place(std::span<double> values);
  // For pisco::SharedTodOptions::mpi_communicator: MPI_COMM_WORLD's address when parallel, else null.
  const void* mpi_communicator() const;

  // Early stop on an error elsewhere: non-blocking checks, each a collective every process posts in
  // the same order. post(failed) after each of this process's jobs; stop() says whether a completed
  // check saw a failure; finish(total, failed) posts the rest up to `total` and waits for all.
  void post_check(bool failed);
  bool stop();
  void finish_checks(std::size_t total, bool failed);

 private:
  int rank_ = 0, size_ = 1, node_rank_ = 0, node_size_ = 1;
  std::size_t posted_ = 0;
  bool stop_ = false;
  struct Checks;
  Checks* checks_ = nullptr;
};

}  // namespace pisco_cli
