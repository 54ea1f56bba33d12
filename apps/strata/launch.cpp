// strata command line — MPI start-up (see launch.hpp). A build with MPI still runs as one
// process without touching MPI when it was not started by mpirun, so that MPI does not
// need to be set up for a user who does not use it.
#include "launch.hpp"

#include <cstdlib>

#ifdef STRATA_HAVE_MPI
#include "strata/mpi.hpp"
#endif

namespace strata::cli {
namespace {
bool initialized = false;

bool under_mpirun() {
  for (const char* v : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK"})
    if (std::getenv(v) != nullptr) return true;
  return false;
}
}  // namespace

Communicator launch(int* argc, char*** argv) {
#ifdef STRATA_HAVE_MPI
  if (under_mpirun()) {
    int provided = 0;
    MPI_Init_thread(argc, argv, MPI_THREAD_SERIALIZED, &provided);
    initialized = true;
    return mpi_communicator(MPI_COMM_WORLD);
  }
#endif
  (void)argc;
  (void)argv;
  return Communicator();
}

bool all_ok(const Communicator& comm, bool ok) {
#ifdef STRATA_HAVE_MPI
  if (initialized && comm.size() > 1) {
    int in = ok ? 1 : 0, out = 0;
    MPI_Allreduce(&in, &out, 1, MPI_INT, MPI_LAND, MPI_COMM_WORLD);
    return out != 0;
  }
#endif
  (void)comm;
  return ok;
}

void finish() {
#ifdef STRATA_HAVE_MPI
  if (initialized) MPI_Finalize();
  initialized = false;
#endif
}

}  // namespace strata::cli
