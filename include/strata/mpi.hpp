// strata — a Communicator from an MPI communicator. Include this header (it includes
// mpi.h) only in programs built against the MPI that strata was built with (CMake option
// STRATA_MPI, OpenMPI on Debian); strata/distributed.hpp alone needs no MPI.
#pragma once

#include <mpi.h>

#include "strata/distributed.hpp"

namespace strata {

/// A Communicator over the processes of `comm`, which must stay valid while it is used.
/// strata works on its own duplicate (MPI_Comm_dup, collective over `comm`), so its
/// messages never match the caller's. MPI must be initialized (MPI_Init or
/// MPI_Init_thread; strata calls MPI from one thread at a time, MPI_THREAD_SERIALIZED is
/// enough); the duplicate is freed when the last copy of the Communicator goes, which
/// must be before MPI_Finalize. Throws NotSupported in a build without MPI (the function
/// is then not defined, and a program that calls it does not link).
Communicator mpi_communicator(MPI_Comm comm);

}  // namespace strata
