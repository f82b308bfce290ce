// The processes of a run (cluster.hpp): MPI in the MPI build, one process otherwise.
#include "cluster.hpp"

#include "pisco/output_file.hpp"

#include <algorithm>
#include <cstdio>
#include <deque>
#include <vector>

#ifdef PISCO_WITH_MPI
// MPI's C interface only (Open MPI and MPICH otherwise add C++ bindings needing a library of their own).
#define OMPI_SKIP_MPICXX 1
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>
#endif

namespace pisco_cli {
namespace {
Cluster* the_cluster = nullptr;
}

Cluster& Cluster::get() { return *the_cluster; }

void Cluster::step(const std::function<void()>& f) {
  if (!parallel()) {
    f();
    return;
  }
  std::optional<std::string> error;
  try {
    f();
  } catch (const std::exception& e) {
    error = e.what();
  }
  agree(error);
}

#ifndef PISCO_WITH_MPI

struct Cluster::Checks {};
Cluster::Cluster(int&, char**&) { the_cluster = this; }
Cluster::~Cluster() { the_cluster = nullptr; }
void Cluster::agree(const std::optional<std::string>& error) {
  if (error) throw AgreedError(*error);
}
std::string Cluster::broadcast(const std::string& text) { return text; }
void Cluster::barrier() {}
double Cluster::max(double v) { return v; }
std::uint64_t Cluster::sum(std::uint64_t v) { return v; }
double Cluster::sum_of(double v) { return v; }
std::uint64_t Cluster::reduce(pisco::BinnedMapmaker&) { return 0; }
void Cluster::sum_in_place(std::span<double>) {}
const void* Cluster::mpi_communicator() const { return nullptr; }
void Cluster::post_check(bool) {}
void Cluster::abort(int) {}
void Cluster::finalize() {}
bool Cluster::stop() { return false; }
void Cluster::finish_checks(std::size_t, bool) {}

#else

struct Cluster::Checks {
  struct Check {
    MPI_Request request = MPI_REQUEST_NULL;
    int in = 0, out = 0;
  };
  std::deque<Check> pending;  // stable addresses: the buffers of the requests
};

Cluster::Cluster(int& argc, char**& argv) {
  the_cluster = this;
  int provided = 0;
  // Only the main thread calls MPI (the engine's threads never do).
  MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
  MPI_Comm node;
  MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, rank_, MPI_INFO_NULL, &node);
  MPI_Comm_rank(node, &node_rank_);
  MPI_Comm_size(node, &node_size_);
  MPI_Comm_free(&node);
  checks_ = new Checks;
}

Cluster::~Cluster() {
  finalize();
  the_cluster = nullptr;
}

void Cluster::finalize() {
  delete checks_;
  checks_ = nullptr;
  int finalized = 0;
  MPI_Finalized(&finalized);
  if (!finalized) MPI_Finalize();
}

void Cluster::agree(const std::optional<std::string>& error) {
  if (!parallel()) {
    if (error) throw AgreedError(*error);
    return;
  }
  int mine = error ? rank_ : size_, first = size_;
  MPI_Allreduce(&mine, &first, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
  if (first == size_) return;
  unsigned long long length = rank_ == first ? error->size() : 0;
  MPI_Bcast(&length, 1, MPI_UNSIGNED_LONG_LONG, first, MPI_COMM_WORLD);
  std::string text = rank_ == first ? *error : std::string(length, '\0');
  MPI_Bcast(text.data(), static_cast<int>(length), MPI_CHAR, first, MPI_COMM_WORLD);
  throw AgreedError("rank " + std::to_string(first) + ": " + text);
}

std::string Cluster::broadcast(const std::string& text) {
  if (!parallel()) return text;
  unsigned long long length = text.size();
  MPI_Bcast(&length, 1, MPI_UNSIGNED_LONG_LONG, 0, MPI_COMM_WORLD);
  std::string out = leader() ? text : std::string(length, '\0');
  MPI_Bcast(out.data(), static_cast<int>(length), MPI_CHAR, 0, MPI_COMM_WORLD);
  return out;
}

void Cluster::barrier() {
  if (parallel()) MPI_Barrier(MPI_COMM_WORLD);
}

double Cluster::max(double v) {
  double out = v;
  if (parallel()) MPI_Allreduce(&v, &out, 1, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
  return out;
}

std::uint64_t Cluster::sum(std::uint64_t v) {
  unsigned long long in = v, out = v;
  if (parallel()) MPI_Allreduce(&in, &out, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
  return out;
}

double Cluster::sum_of(double v) {
  double out = v;
  if (parallel()) MPI_Allreduce(&v, &out, 1, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  return out;
}

namespace {
// Arrays in pieces of at most 2^26 values (MPI counts are ints).
constexpr std::size_t kPiece = std::size_t(1) << 26;
template <class T>
void send_all(const T* data, std::size_t n, MPI_Datatype type, int to) {
  for (std::size_t i = 0; i < n; i += kPiece)
    MPI_Send(data + i, static_cast<int>(std::min(kPiece, n - i)), type, to, 7, MPI_COMM_WORLD);
}
template <class T>
void recv_all(T* data, std::size_t n, MPI_Datatype type, int from) {
  for (std::size_t i = 0; i < n; i += kPiece)
    MPI_Recv(data + i, static_cast<int>(std::min(kPiece, n - i)), type, from, 7, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
}
}  // namespace

std::uint64_t Cluster::reduce(pisco::BinnedMapmaker& mapper) {
  std::uint64_t sent = 0;
  std::vector<double> ata, atd;
  std::vector<std::uint32_t> hits;
  for (int step = 1; step < size_; step <<= 1) {
    if (rank_ % (2 * step) == 0) {
      const int from = rank_ + step;
      if (from >= size_) continue;
      ata.resize(mapper.normal_matrices().size());
      atd.resize(mapper.normal_vectors().size());
      hits.resize(mapper.hits().size());
      recv_all(ata.data(), ata.size(), MPI_DOUBLE, from);
      recv_all(atd.data(), atd.size(), MPI_DOUBLE, from);
      recv_all(hits.data(), hits.size(), MPI_UINT32_T, from);
      mapper.add_normal_equations(ata, atd, hits);
    } else {
      const int to = rank_ - step;
      send_all(mapper.normal_matrices().data(), mapper.normal_matrices().size(), MPI_DOUBLE, to);
      send_all(mapper.normal_vectors().data(), mapper.normal_vectors().size(), MPI_DOUBLE, to);
      send_all(mapper.hits().data(), mapper.hits().size(), MPI_UINT32_T, to);
      sent += 8 * (mapper.normal_matrices().size() + mapper.normal_vectors().size()) + 4 * mapper.hits().size();
      break;
    }
  }
  return sent;
}

void Cluster::sum_in_place(std::span<double> values) {
  if (!parallel()) return;
  std::vector<double> other;
  for (int step = 1; step < size_; step <<= 1) {
    if (rank_ % (2 * step) == 0) {
      const int from = rank_ + step;
      if (from >= size_) continue;
      other.resize(values.size());
      recv_all(other.data(), other.size(), MPI_DOUBLE, from);
      for (std::size_t i = 0; i < values.size(); ++i) values[i] += other[i];
    } else {
      send_all(values.data(), values.size(), MPI_DOUBLE, rank_ - step);
      break;
    }
  }
  for (std::size_t i = 0; i < values.size(); i += kPiece)
    MPI_Bcast(values.data() + i, static_cast<int>(std::min(kPiece, values.size() - i)), MPI_DOUBLE, 0, MPI_COMM_WORLD);
}

const void* Cluster::mpi_communicator() const {
  static const MPI_Comm world = MPI_COMM_WORLD;
  return parallel() ? &world : nullptr;
}

void Cluster::abort(int status) {
  if (!parallel()) return;
  std::fflush(nullptr);
  pisco::remove_temporary_files();
  MPI_Abort(MPI_COMM_WORLD, status);
}

void Cluster::post_check(bool failed) {
  if (!parallel()) return;
  auto& c = checks_->pending.emplace_back();
  c.in = failed ? 1 : 0;
  MPI_Iallreduce(&c.in, &c.out, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD, &c.request);
  ++posted_;
}

bool Cluster::stop() {
  if (!parallel()) return false;
  while (!checks_->pending.empty()) {
    auto& c = checks_->pending.front();
    int done = 0;
    MPI_Test(&c.request, &done, MPI_STATUS_IGNORE);
    if (!done) break;
    stop_ = stop_ || c.out != 0;
    checks_->pending.pop_front();
  }
  return stop_;
}

void Cluster::finish_checks(std::size_t total, bool failed) {
  if (!parallel()) return;
  while (posted_ < total) post_check(failed);
  for (auto& c : checks_->pending) MPI_Wait(&c.request, MPI_STATUS_IGNORE);
  checks_->pending.clear();
  posted_ = 0;
  stop_ = false;
}

#endif

}  // namespace pisco_cli
