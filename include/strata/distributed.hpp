// strata — the solver over several processes (MPI ranks): one machine's solver per rank,
// the assembly tree split across the ranks (docs/distributed.md).
//
// Usage (every rank makes the same calls; the matrix and the right-hand sides are read
// on rank 0 only, the other ranks pass an empty matrix and null pointers):
//
//   #include <strata/mpi.hpp>           // only where MPI_Comm is needed
//   strata::DistributedSolver solver(strata::mpi_communicator(MPI_COMM_WORLD), options);
//   solver.analyze(A);                  // rank 0 analyzes; the result is broadcast
//   solver.factorize(A);                // every rank factors its subtrees, rank 0 the top
//   solver.solve(b, x, nrhs);           // x gathered on rank 0
//
// This header does not include mpi.h: a Communicator is made from an MPI_Comm by
// strata/mpi.hpp (builds with STRATA_MPI), and the default Communicator is one process
// without MPI, so that the same program runs on one rank where MPI is not installed.
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "strata/errors.hpp"
#include "strata/options.hpp"
#include "strata/sparse_matrix.hpp"
#include "strata/stats.hpp"

namespace strata {

namespace detail {
class CommImpl;  // src/distributed/comm.hpp
struct DistributedState;
struct DistributedAccess;  // test hooks (src/distributed/distributed_internal.hpp)
}  // namespace detail

/// A group of processes that solve together. The default is one process (rank 0 of 1,
/// no MPI); strata::mpi_communicator (strata/mpi.hpp) wraps an MPI communicator.
/// Copies share the underlying communicator.
class Communicator {
 public:
  /// One process, no MPI.
  Communicator();
  explicit Communicator(std::shared_ptr<detail::CommImpl> impl);
  /// This process's rank, 0-based.
  int rank() const;
  /// Number of processes.
  int size() const;
  /// Rank among the processes of the same machine (the GPU it picks is derived from it).
  int local_rank() const;
  /// Bytes this process sent / received through the communicator since it was made.
  std::size_t bytes_sent() const;
  std::size_t bytes_received() const;
  /// True when this build has MPI support (CMake option STRATA_MPI).
  static bool mpi_available();
  const std::shared_ptr<detail::CommImpl>& impl() const { return impl_; }

 private:
  std::shared_ptr<detail::CommImpl> impl_;
};

/// What one rank did in the last factorization and the last solve.
struct RankStats {
  int rank = 0;
  int workers = 1;            ///< executors (GPUs, or 1 CPU executor) on it
  index_t subtrees = 0;       ///< subtrees it factored
  double factor_flops = 0;    ///< Σ front flops (Cholesky count) it factored
  double factor_seconds = 0;  ///< its part of the factorization, wall time
  /// Wall time, s, before its part: the scaled values sent (rank 0, to every other rank)
  /// or received (the others), by MPI from host memory.
  double values_seconds = 0;
  /// Of factor_seconds, the exchange after its subtrees: agreeing on errors, the subtree
  /// roots' contribution blocks to rank 0 (waiting for the last of them on rank 0) and
  /// the pivot statistics.
  double exchange_seconds = 0;
  /// Of exchange_seconds, the contribution blocks' transfer alone (packing, sends and
  /// receives, unpacking, up to their arrival), after the ranks agreed that none failed.
  double blocks_seconds = 0;
  std::size_t factor_bytes_sent = 0;      ///< values (rank 0), blocks, pivot statistics
  std::size_t factor_bytes_received = 0;  ///< its scaled values, blocks (rank 0)
  /// Bytes of scaled matrix values in the last factorize / refactorize call (part of the
  /// two above): on a rank r > 0 those it received, 8 × (entries its subtrees' fronts
  /// assemble); on rank 0 the sum it sent to the others. An automatic type that falls
  /// back from Cholesky to LDLᵀ sends them twice.
  std::size_t values_bytes = 0;
  double solve_seconds = 0;  ///< its part of the last solve (all refinement steps)
  std::size_t solve_bytes_sent = 0;
  std::size_t solve_bytes_received = 0;
  std::size_t factor_bytes_held = 0;  ///< doubles×8 of the factor panels stored on it
};

/// Figures of the distributed run (complete on rank 0; the other ranks see their own).
struct DistributedStats {
  int ranks = 1;
  int workers_per_rank = 1;
  std::size_t analysis_bytes = 0;  ///< size of the broadcast analysis
  double analysis_broadcast_seconds = 0;
  /// How the subtree roots' contribution blocks go to rank 0: "nccl" (GPU to GPU, a build
  /// with STRATA_NCCL and GPU ranks), "mpi" (host buffers), "" with one rank.
  std::string blocks_transport;
  std::vector<RankStats> per_rank;  ///< one per rank, by rank (rank 0: all of them)
};

/// The direct solver over the ranks of a Communicator. Collective: every rank calls every
/// method, in the same order. The nested-dissection tree is split for ranks × workers
/// per rank workers (schedule/tree_partition.hpp); each rank factors the subtrees of its
/// workers with the single-machine code (CPU executor, or one CUDA executor per GPU with
/// Backend::cuda and Options::num_gpus), sends the subtree roots' contribution blocks to
/// rank 0, which factors the top of the tree. The factor stays distributed; solves run
/// across the ranks (forward and backward substitution on each rank's subtrees, the top on
/// rank 0) and iterative refinement is driven by rank 0. With one rank this is Solver.
/// Errors: what a phase throws on one rank is thrown, with the same type and message, on
/// every rank.
class DistributedSolver {
 public:
  /// `comm` and `options` (every rank should pass the same options).
  explicit DistributedSolver(Communicator comm, Options options = {});
  ~DistributedSolver();
  DistributedSolver(DistributedSolver&&) noexcept;
  DistributedSolver& operator=(DistributedSolver&&) noexcept;
  DistributedSolver(const DistributedSolver&) = delete;
  DistributedSolver& operator=(const DistributedSolver&) = delete;

  /// Collective. Rank 0 analyzes A (as Solver::analyze) and broadcasts the analysis; the
  /// other ranks' `a` is ignored (pass an empty SparseMatrix). Throws as Solver::analyze.
  void analyze(const SparseMatrix& a);
  /// Collective. Rank 0 scales A's values and sends each rank the ones its subtrees
  /// assemble (RankStats::values_bytes); every rank factors its
  /// subtrees; rank 0 factors the top part. A is read on rank 0 only. Throws as
  /// Solver::factorize.
  void factorize(const SparseMatrix& a);
  /// Collective: as factorize, with the analyzed pattern (Solver::refactorize).
  void refactorize(const SparseMatrix& a);
  /// Collective. b (n×nrhs, column-major) on rank 0; x (n×nrhs) filled on rank 0; the
  /// other ranks pass nullptr for both and the same nrhs. Iterative refinement as
  /// Solver::solve, every step a distributed solve. Throws as Solver::solve.
  void solve(const double* b, double* x, index_t nrhs = 1);
  /// Convenience overload (rank 0: b of size n·nrhs; other ranks: b empty, returns empty).
  /// The other ranks must call it too; nrhs is taken from rank 0.
  std::vector<double> solve(const std::vector<double>& b);

  /// n of the analyzed matrix (every rank).
  index_t size() const;
  /// Statistics of the last call of each phase (complete on rank 0).
  const Stats& stats() const;
  const DistributedStats& distributed_stats() const;
  const Communicator& communicator() const;

 private:
  friend struct detail::DistributedAccess;
  std::unique_ptr<detail::DistributedState> state_;
};

}  // namespace strata
