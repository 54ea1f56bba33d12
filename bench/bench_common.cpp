// strata benchmarks — shared pieces (see bench_common.hpp).
#include "bench_common.hpp"

#include <cholmod.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <thread>

#include "base/atomic_file.hpp"
#include "base/timer.hpp"
#include "blas_kernels.hpp"
#include "core/stats_json.hpp"
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

int run_driver(int argc, char** argv, int (*body)(int, char**)) {
  app::use_fitting_blas_kernels(argv);  // every solver of the run gets the same kernels
  try {
    return body(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: %s\n",
                 std::filesystem::path(argc > 0 ? argv[0] : "bench").filename().c_str(), e.what());
    return 1;
  }
}

Problem load_problem(const std::string& name) {
  Problem p;
  p.name = name;
  const auto ends_with = [&](const std::string& x) {
    return name.size() >= x.size() && name.compare(name.size() - x.size(), x.size(), x) == 0;
  };
  if (name.find('/') != std::string::npos && (ends_with(".mtx") || ends_with(".mtx.gz"))) {
    MMMatrix mm = read_matrix_market(name);
    p.name = std::filesystem::path(name).filename().string();
    p.name = p.name.substr(0, p.name.find(".mtx"));
    p.symmetric = mm.symmetry != MMSymmetry::general;
    p.a = std::move(mm.matrix);
    return p;
  }
  auto dash = name.find('-');
  if (dash != std::string::npos) {
    const std::string kind = name.substr(0, dash);
    index_t k = 0;
    const char* end = name.data() + name.size();
    const auto [at, ec] = std::from_chars(name.data() + dash + 1, end, k);
    if (ec != std::errc() || at != end || k < 1)
      throw InvalidInput("problem '" + name + "': the size after '-' must be a positive integer");
    if (kind == "lap3d")
      p.a = generators::laplacian_3d(k, k, k);
    else if (kind == "lap2d")
      p.a = generators::laplacian_2d(k, k);
    else if (kind == "elast3d")
      p.a = generators::elasticity_3d(k, k, k);
    else if (kind == "uelast3d") {
      // unsymmetric values on the elasticity pattern: entry (i, j) scaled by
      // 1 + 0.3·sin(i + 2j), deterministic (the LU benchmark problem)
      p.a = expand_symmetric(generators::elasticity_3d(k, k, k));
      for (index_t j = 0; j < p.a.n_cols; ++j)
        for (index_t q = p.a.offsets[j]; q < p.a.offsets[j + 1]; ++q)
          p.a.values[q] *= 1.0 + 0.3 * std::sin(static_cast<double>(p.a.indices[q] + 2 * j));
      p.symmetric = false;
    } else
      throw InvalidInput("unknown generated problem " + name);
    return p;
  }
  MMMatrix mm = read_matrix_market(std::string(STRATA_MATRIX_DIR) + "/" + name + ".mtx.gz");
  p.symmetric = mm.symmetry != MMSymmetry::general;
  p.a = std::move(mm.matrix);
  return p;
}

// The commit prepare.sh recorded in .carry/COMMIT (the working directory is the
// repository's root on the lent GPU machine), or "" when the run is not a carried one
// (STRATA_CARRIED=1, set by the scripts/gpu run scripts): the binaries there were built
// here, and the machine's own checkout says nothing about them.
namespace {
std::string carried_commit() {
  const char* carried = std::getenv("STRATA_CARRIED");
  if (!carried || std::string(carried) != "1") return "";
  std::ifstream f(".carry/COMMIT");
  std::string line;
  std::getline(f, line);
  return line;
}
}  // namespace

nlohmann::json run_metadata(int argc, char** argv) {
  const std::string carried = carried_commit();
  std::string cmd;
  for (int i = 0; i < argc; ++i) cmd += (i ? " " : "") + std::string(argv[i]);
  std::string cpu = command_output("grep -m1 'model name' /proc/cpuinfo | cut -d: -f2");
  while (!cpu.empty() && cpu.front() == ' ') cpu.erase(cpu.begin());
  char host[256] = {0};
  gethostname(host, sizeof host - 1);
  return {
      {"date", utc_now("%Y-%m-%dT%H:%M:%SZ")},
      {"command", cmd},
      {"git_commit", !carried.empty() ? carried.substr(0, carried.find(' '))
                                      : command_output("git -C " STRATA_SOURCE_DIR
                                                       " rev-parse --short HEAD 2>/dev/null")},
      {"git_dirty", !carried.empty()
                        ? carried.find("uncommitted") != std::string::npos
                        : !command_output("git -C " STRATA_SOURCE_DIR
                                          " status --porcelain --untracked-files=no 2>/dev/null")
                               .empty()},
      {"machine",
       {{"host", host},
        {"cpu", cpu},
        {"hardware_threads", std::thread::hardware_concurrency()},
        {"blas", app::blas_description()},
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
  // temporary name in the same folder, fsync, rename (base/atomic_file.hpp): a reader or
  // bench/report.py never sees a half-written result
  write_file_atomically(path, j.dump(2) + "\n");
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

double berr(const SparseMatrix& a, const std::vector<double>& x, const std::vector<double>& b) {
  std::vector<double> ax(b.size());
  multiply(a, x.data(), ax.data());
  std::vector<double> row(a.n_rows, 0.0);
  for (index_t j = 0; j < a.n_cols; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      row[a.indices[p]] += std::abs(a.values[p]);
      if (a.storage != Storage::full && a.indices[p] != j) row[j] += std::abs(a.values[p]);
    }
  double an = 0, rn = 0, xn = 0, bn = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    an = std::max(an, row[i]);
    rn = std::max(rn, std::abs(b[i] - ax[i]));
    xn = std::max(xn, std::abs(x[i]));
    bn = std::max(bn, std::abs(b[i]));
  }
  return rn / (an * xn + bn);
}

RefResult run_cholmod(const SparseMatrix& a, const std::vector<index_t>& perm,
                      const std::vector<double>& b, int repeat) {
  RefResult r;
  cholmod_common cc;
  cholmod_l_start(&cc);
  cc.nmethods = 1;
  cc.method[0].ordering = CHOLMOD_GIVEN;
  cc.supernodal = CHOLMOD_SUPERNODAL;
  const index_t n = a.n_rows;
  cholmod_sparse* A = cholmod_l_allocate_sparse(n, n, a.nnz(), 1, 1, -1, CHOLMOD_REAL, &cc);
  std::copy(a.offsets.begin(), a.offsets.end(), static_cast<SuiteSparse_long*>(A->p));
  std::copy(a.indices.begin(), a.indices.end(), static_cast<SuiteSparse_long*>(A->i));
  std::copy(a.values.begin(), a.values.end(), static_cast<double*>(A->x));
  std::vector<SuiteSparse_long> p(perm.begin(), perm.end());
  cholmod_factor* L = cholmod_l_analyze_p(A, p.data(), nullptr, 0, &cc);
  std::vector<double> times;
  for (int k = 0; k < repeat; ++k) {
    Timer t;
    cholmod_l_factorize(A, L, &cc);
    times.push_back(t.seconds());
  }
  r.ok = cc.status == CHOLMOD_OK;
  r.seconds = bench::median(times);
  r.lnz = cc.lnz;
  cholmod_dense* B = cholmod_l_allocate_dense(n, 1, n, CHOLMOD_REAL, &cc);
  std::copy(b.begin(), b.end(), static_cast<double*>(B->x));
  cholmod_dense* X = nullptr;
  times.clear();
  for (int k = 0; k < std::max(repeat, 1); ++k) {
    if (X) cholmod_l_free_dense(&X, &cc);
    Timer t;
    X = cholmod_l_solve(CHOLMOD_A, L, B, &cc);
    times.push_back(t.seconds());
  }
  r.solve_seconds = bench::median(times);
  std::vector<double> x(static_cast<double*>(X->x), static_cast<double*>(X->x) + n);
  r.backward_error = berr(a, x, b);
  cholmod_l_free_dense(&X, &cc);
  cholmod_l_free_dense(&B, &cc);
  cholmod_l_free_factor(&L, &cc);
  cholmod_l_free_sparse(&A, &cc);
  cholmod_l_finish(&cc);
  return r;
}

nlohmann::json device_figures(const FactorStats& fs) {
  const nlohmann::json all = fs;  // the one vocabulary of the statistics (core/stats_json.hpp)
  nlohmann::json j;
  for (const char* key : {"seconds", "input_seconds", "values_scaled_on_device", "gflops",
                          "device_seconds", "bytes_to_device", "bytes_to_host", "device_batches",
                          "device_fused_batches", "tiled_fronts", "lu_large_fronts",
                          "lu_large_fronts_pivoted", "lu_large_fronts_batched", "factor_resident"})
    j[key] = all.at(key);
  j["phases"] = all.at("device_phases");  // the results files' name for them
  return j;
}

}  // namespace strata::bench
