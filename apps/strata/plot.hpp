// strata command line — plots of a simulation's output folder (`strata simulate --plot`,
// `strata plot DIR`), drawn by python/strata/_plot.py with matplotlib.
#pragma once

#include <string>

namespace strata::cli {

/// Writes FOLDER/summary.png (energy, constraint violation, step size, Newton iterations
/// and time per step against time) and, when `coordinates` (comma-separated names such
/// as "chassis.x,crank.phi") is not empty, FOLDER/coordinates.png. The plot script is
/// compiled into the binary and run by the first Python 3 with matplotlib among
/// $STRATA_PYTHON (alone, when set), the interpreter of the build, `python3` on PATH and
/// /usr/bin/python3. Returns 0 when written, 1 when the script rejected the folder or a
/// coordinate (it printed why, "strata: error: ..."); throws strata::Error when no such
/// interpreter exists.
int run_plot(const std::string& folder, const std::string& coordinates, const std::string& title);

}  // namespace strata::cli
