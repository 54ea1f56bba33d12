// strata command line — running the plot script (see plot.hpp).
#include "plot.hpp"

#include <spawn.h>
#include <sys/wait.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "plot_script.hpp"
#include "strata/errors.hpp"

extern char** environ;

namespace strata::cli {
namespace {

constexpr int kNotStarted = -1;
// the script's exit status when its interpreter cannot import matplotlib
constexpr int kNoMatplotlib = 3;

/// Runs argv (PATH search when argv[0] has no '/') and waits: its exit status, or
/// kNotStarted when it could not be executed.
int spawn_and_wait(const std::vector<std::string>& args) {
  std::vector<char*> argv;
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  pid_t pid = 0;
  if (posix_spawnp(&pid, argv[0], nullptr, nullptr, argv.data(), environ) != 0) return kNotStarted;
  int status = 0;
  while (waitpid(pid, &status, 0) < 0)
    if (errno != EINTR) return kNotStarted;
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  return 128 + (WIFSIGNALED(status) ? WTERMSIG(status) : 0);
}

std::vector<std::string> interpreters() {
  if (const char* env = std::getenv("STRATA_PYTHON"); env && *env) return {env};
  std::vector<std::string> out;
  for (const std::string c :
       {std::string(kBuildPython), std::string("python3"), std::string("/usr/bin/python3")})
    if (!c.empty() && std::find(out.begin(), out.end(), c) == out.end()) out.push_back(c);
  return out;
}

}  // namespace

int run_plot(const std::string& folder, const std::string& coordinates, const std::string& title) {
  std::fflush(stdout);  // what the command printed so far comes before the script's lines
  std::string tried;
  for (const std::string& python : interpreters()) {
    std::vector<std::string> args = {python, "-c", kPlotScript, folder};
    if (!coordinates.empty()) args.insert(args.end(), {"--coordinates", coordinates});
    if (!title.empty()) args.insert(args.end(), {"--title", title});
    const int rc = spawn_and_wait(args);
    if (rc == 0) return 0;
    if (rc != kNotStarted && rc != kNoMatplotlib) return 1;  // the script said why
    tried += (tried.empty() ? "" : ", ") + python +
             (rc == kNotStarted ? " (cannot be run)" : " (no matplotlib)");
  }
  throw Error("plotting needs Python 3 with matplotlib; tried " + tried +
              " (scripts/setup.sh installs python3-matplotlib; STRATA_PYTHON names another "
              "interpreter)");
}

}  // namespace strata::cli
