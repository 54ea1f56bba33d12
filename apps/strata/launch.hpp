// strata command line — the processes it runs on: one, or the ranks of `mpirun -n R`.
#pragma once

#include "strata/distributed.hpp"

namespace strata::cli {

/// Started by mpirun/mpiexec (OpenMPI's OMPI_COMM_WORLD_SIZE, or PMI_SIZE / PMIX_RANK in
/// the environment) in a build with MPI: initializes MPI (finalized by finish()) and
/// returns the world; otherwise one process without MPI.
Communicator launch(int* argc, char*** argv);

/// True on every rank when `ok` is true on every rank (one process: ok).
bool all_ok(const Communicator& comm, bool ok);

/// Finalizes MPI when launch() initialized it. Every Communicator must be gone.
void finish();

}  // namespace strata::cli
