// strata benchmarks — shared pieces (see bench_common.hpp).
#include "bench_common.hpp"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <thread>

#include "sparse/generators.hpp"
#include "strata/errors.hpp"
#include "strata/matrix_market.hpp"

namespace strata::bench {
namespace {

std::string command_output(const std::string& cmd) {
  std::string out;
  if (FILE* p = popen(cmd.c_str(), "r")) {
    char buf[512];
    while (fgets(buf, sizeof buf, p)) out += buf;
    pclose(p);
  }
  while (!out.empty() && (out.back() == '\n' || out.back() == ' ')) out.pop_back();
  return out;
}

std::string utc_now(const char* fmt) {
  std::time_t t = std::time(nullptr);
  char buf[64];
  std::strftime(buf, sizeof buf, fmt, std::gmtime(&t));
  return buf;
}

}  // namespace

Problem load_problem(const std::string& name) {
  Problem p;
  p.name = name;
  auto dash = name.find('-');
  if (dash != std::string::npos) {
    const std::string kind = name.substr(0, dash);
    const index_t k = std::stoll(name.substr(dash + 1));
    if (kind == "lap3d")
      p.a = generators::laplacian_3d(k, k, k);
    else if (kind == "lap2d")
      p.a = generators::laplacian_2d(k, k);
    else if (kind == "elast3d")
      p.a = generators::elasticity_3d(k, k, k);
    else
      throw InvalidInput("unknown generated problem " + name);
    return p;
  }
  MMMatrix mm = read_matrix_market(std::string(STRATA_MATRIX_DIR) + "/" + name + ".mtx.gz");
  p.symmetric = mm.symmetry != MMSymmetry::general;
  p.a = std::move(mm.matrix);
  return p;
}

nlohmann::json run_metadata(int argc, char** argv) {
  std::string cmd;
  for (int i = 0; i < argc; ++i) cmd += (i ? " " : "") + std::string(argv[i]);
  std::string cpu = command_output("grep -m1 'model name' /proc/cpuinfo | cut -d: -f2");
  while (!cpu.empty() && cpu.front() == ' ') cpu.erase(cpu.begin());
  char host[256] = {0};
  gethostname(host, sizeof host - 1);
  return {
      {"date", utc_now("%Y-%m-%dT%H:%M:%SZ")},
      {"command", cmd},
      {"git_commit",
       command_output("git -C " STRATA_SOURCE_DIR " rev-parse --short HEAD 2>/dev/null")},
      {"git_dirty", !command_output("git -C " STRATA_SOURCE_DIR
                                    " status --porcelain --untracked-files=no 2>/dev/null")
                         .empty()},
      {"machine",
       {{"host", host},
        {"cpu", cpu},
        {"hardware_threads", std::thread::hardware_concurrency()},
        {"gpu", command_output(
                    "nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1")}}}};
}

std::string write_result(const nlohmann::json& j, const std::string& stem,
                         const std::string& results_dir) {
  const std::string dir =
      results_dir.empty() ? std::string(STRATA_SOURCE_DIR) + "/bench/results" : results_dir;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw Error("cannot create " + dir + ": " + ec.message());
  const std::string path = dir + "/" + stem + "-" + utc_now("%Y%m%dT%H%M%SZ") + ".json";
  const std::string tmp = path + ".tmp";
  {
    std::ofstream f(tmp);
    f << j.dump(2) << "\n";
    if (!f) {
      std::remove(tmp.c_str());
      throw Error("cannot write " + tmp);
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw Error("cannot rename " + tmp + " to " + path);
  }
  return path;
}

std::string check_tag(const std::string& tag) {
  for (char c : tag)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-'))
      return "tag '" + tag + "' may hold only letters, digits, '.', '_' and '-'";
  return {};
}

double geometric_mean(const std::vector<double>& v) {
  if (v.empty()) return 0;
  double s = 0;
  for (double x : v) s += std::log(x);
  return std::exp(s / v.size());
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

}  // namespace strata::bench
