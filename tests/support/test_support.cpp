// strata tests — shared helpers (see test_support.hpp).
#include "support/test_support.hpp"

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <limits>
#include <numeric>
#include <set>
#include <thread>
#include <tuple>

#include "analysis/analysis.hpp"
#include "base/blas.hpp"
#include "numeric/factor.hpp"

extern "C" void dgecon_(const char* norm, const int* n, const double* a, const int* lda,
                        const double* anorm, double* rcond, double* work, int* iwork, int* info);

namespace strata::test {

std::string matrix_path(const std::string& name) {
  return std::string(STRATA_MATRIX_DIR) + "/" + name + ".mtx.gz";
}

std::vector<std::string> shared_matrix_names() {
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(STRATA_MATRIX_DIR)) {
    const std::string f = e.path().filename().string();
    const std::string ext = ".mtx.gz";
    if (f.size() > ext.size() && f.compare(f.size() - ext.size(), ext.size(), ext) == 0)
      names.push_back(f.substr(0, f.size() - ext.size()));
  }
  std::sort(names.begin(), names.end());
  return names;
}

std::string unique_temp_path(const std::string& name) {
  std::random_device rd;
  return (std::filesystem::temp_directory_path() /
          (name + "." + std::to_string(::getpid()) + "." + std::to_string(rd())))
      .string();
}

std::mt19937_64 fresh_rng(unsigned long long* seed_out) {
  std::random_device rd;
  unsigned long long seed = (static_cast<unsigned long long>(rd()) << 32) ^ rd();
  if (const char* fixed = std::getenv("STRATA_TEST_SEED"); fixed && *fixed)
    seed = std::strtoull(fixed, nullptr, 10);
  if (seed_out) *seed_out = seed;
  return std::mt19937_64(seed);
}

SparseMatrix random_pattern_with_diagonal(index_t n, index_t per_column, std::mt19937_64& rng) {
  std::uniform_int_distribution<index_t> pick(0, n - 1);
  std::vector<std::vector<index_t>> cols(n);
  for (index_t j = 0; j < n; ++j) {
    cols[j].push_back(j);
    for (index_t q = 0; q < per_column && n > 1; ++q) {
      const index_t i = pick(rng);
      cols[j].push_back(i);
      if (q % 2 == 0) cols[i].push_back(j);
    }
  }
  SparseMatrix a;
  a.n_rows = a.n_cols = n;
  a.offsets.assign(n + 1, 0);
  for (index_t j = 0; j < n; ++j) {
    std::sort(cols[j].begin(), cols[j].end());
    cols[j].erase(std::unique(cols[j].begin(), cols[j].end()), cols[j].end());
    a.offsets[j + 1] = a.offsets[j] + static_cast<index_t>(cols[j].size());
    a.indices.insert(a.indices.end(), cols[j].begin(), cols[j].end());
  }
  a.values.assign(a.indices.size(), 0.0);
  return a;
}

SparseMatrix with_values(const SparseMatrix& pattern, double diag, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  SparseMatrix a = pattern;
  for (index_t j = 0; j < a.n_cols; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
      a.values[p] = a.indices[p] == j ? diag : u(rng);
  return a;
}

bool structurally_nonsingular(const SparseMatrix& a) {
  const index_t n = a.n_cols;
  std::vector<index_t> row_match(n, -1);
  std::vector<char> seen;
  std::function<bool(index_t)> augment = [&](index_t j) {
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      const index_t i = a.indices[p];
      if (a.values[p] == 0.0 || seen[i]) continue;
      seen[i] = 1;
      if (row_match[i] < 0 || augment(row_match[i])) {
        row_match[i] = j;
        return true;
      }
    }
    return false;
  };
  for (index_t j = 0; j < n; ++j) {
    seen.assign(n, 0);
    if (!augment(j)) return false;
  }
  return true;
}

StaleAnalysis stale_analysis(index_t n, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  for (;;) {
    const SparseMatrix pattern = random_pattern_with_diagonal(n, 3, rng);
    StaleAnalysis s{with_values(pattern, 20.0, rng), with_values(pattern, 0.0, rng), {}};
    s.b.resize(n);
    for (double& v : s.b) v = u(rng);
    std::vector<double> x = s.b;
    if (structurally_nonsingular(s.stale) && dense_solve(to_dense(s.stale), n, x, 1)) return s;
  }
}

std::optional<StaleValues> stale_values(const SparseMatrix& pattern, int zero_one_in,
                                        std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  const index_t n = pattern.n_rows;
  StaleValues v{with_values(pattern, 20.0, rng), with_values(pattern, 8.0, rng), {}, {}, 0};
  zero_some_diagonal(v.stale, zero_one_in, rng);
  v.b.resize(n);
  for (double& x : v.b) x = u(rng);
  v.ref = v.b;
  if (!dense_solve(to_dense(v.stale), n, v.ref, 1) || !structurally_nonsingular(v.stale))
    return std::nullopt;
  v.kappa = condition_inf(v.stale);
  if (!(v.kappa < 1e10)) return std::nullopt;
  return v;
}

SparseMatrix with_duplicate_zeros(const SparseMatrix& a) {
  SparseMatrix d = a;
  d.indices.clear();
  d.values.clear();
  for (index_t j = 0; j < a.n_cols; ++j) {
    d.offsets[j] = static_cast<index_t>(d.indices.size());
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      d.indices.push_back(a.indices[p]);
      d.values.push_back(a.values[p]);
    }
    if (a.offsets[j + 1] > a.offsets[j]) {
      d.indices.push_back(a.indices[a.offsets[j]]);
      d.values.push_back(0.0);
    }
  }
  d.offsets[a.n_cols] = static_cast<index_t>(d.indices.size());
  return d;
}

std::vector<ValueChange> value_changes(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> wiggle(0.97, 1.03);
  const std::pair<RandomKind, MatrixType> kinds[] = {
      {RandomKind::general, MatrixType::general},
      {RandomKind::spd, MatrixType::automatic},
      {RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite}};
  std::vector<ValueChange> out;
  for (const auto& [kind, type] : kinds)
    for (index_t n : {1, 2, 3, 5, 733}) {
      ValueChange c{type, n, random_sparse(n, 3, kind, rng), {}};
      c.next = c.a;
      for (double& v : c.next.values) v *= wiggle(rng);
      out.push_back(std::move(c));
    }
  return out;
}

SparseMatrix random_sparse(index_t n, index_t per_column, RandomKind kind, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> val(-1.0, 1.0);
  std::uniform_int_distribution<index_t> row(0, std::max<index_t>(n - 1, 0));
  const bool symmetric = kind != RandomKind::general;
  std::vector<std::set<index_t>> cols(n);
  // A random perfect matching (entries (sigma(j), j)) makes every matrix structurally
  // nonsingular even with zero diagonal entries; random values then make it nonsingular
  // with probability one.
  std::vector<index_t> sigma(n);
  for (index_t j = 0; j < n; ++j) sigma[j] = j;
  std::shuffle(sigma.begin(), sigma.end(), rng);
  for (index_t j = 0; j < n; ++j) {
    const index_t i = sigma[j];
    if (i == j) continue;
    if (symmetric)
      cols[std::min(i, j)].insert(std::max(i, j));
    else
      cols[j].insert(i);
  }
  for (index_t j = 0; j < n; ++j)
    for (index_t t = 0; t < per_column; ++t) {
      index_t i = row(rng);
      if (i == j) continue;
      if (symmetric)
        cols[std::min(i, j)].insert(std::max(i, j));  // lower: row > col
      else
        cols[j].insert(i);
    }
  // Diagonal: spd dominant; indefinite mixed signs with ~1/4 zero diagonals; general
  // with ~1/4 zero diagonals (made nonsingular by the random off-diagonal entries).
  std::vector<double> diag(n);
  std::uniform_int_distribution<int> coin(0, 3);
  for (index_t j = 0; j < n; ++j) {
    switch (kind) {
      case RandomKind::spd:
        diag[j] = 0;
        break;  // set below from row sums
      case RandomKind::symmetric_indefinite:
        diag[j] = coin(rng) == 0 ? 0.0 : (coin(rng) < 2 ? 1.0 : -1.0) * (0.5 + std::abs(val(rng)));
        break;
      case RandomKind::general:
        diag[j] = coin(rng) == 0 ? 0.0 : 2.0 * val(rng);
        break;
    }
  }
  SparseMatrix a;
  a.n_rows = a.n_cols = n;
  a.storage = symmetric ? Storage::lower : Storage::full;
  std::vector<std::vector<double>> vals(n);
  std::vector<double> rowsum(n, 0.0);
  for (index_t j = 0; j < n; ++j)
    for (index_t i : cols[j]) {
      double v = val(rng);
      vals[j].push_back(v);
      rowsum[i] += std::abs(v);
      rowsum[j] += std::abs(v);
    }
  // A zero diagonal in a 1×1 matrix would be singular: keep n = 1 nonsingular.
  for (index_t j = 0; j < n; ++j) {
    if (kind == RandomKind::spd) diag[j] = rowsum[j] + 1.0;
    if (n == 1 && diag[j] == 0.0) diag[j] = 1.0;
  }
  a.offsets.assign(1, 0);
  // where the matching uses the diagonal, the diagonal must be nonzero
  for (index_t j = 0; j < n; ++j)
    if (sigma[j] == j && diag[j] == 0.0) diag[j] = 1.0 + std::abs(val(rng));
  for (index_t j = 0; j < n; ++j) {
    // canonical: sorted rows; the diagonal goes in its sorted place
    std::vector<std::pair<index_t, double>> col;
    if (diag[j] != 0.0 || kind == RandomKind::spd) col.push_back({j, diag[j]});
    index_t t = 0;
    for (index_t i : cols[j]) col.push_back({i, vals[j][t++]});
    std::sort(col.begin(), col.end());
    for (auto& [i, v] : col) {
      a.indices.push_back(i);
      a.values.push_back(v);
    }
    a.offsets.push_back(static_cast<index_t>(a.indices.size()));
  }
  return a;
}

SparseMatrix random_kkt(index_t n, std::mt19937_64& rng, double decades,
                        std::vector<char>* is_constraint) {
  const index_t n2 = n / 3, n1 = n - n2;
  // H: lower, canonical, diagonally dominant with a positive diagonal
  const SparseMatrix h = random_sparse(n1, 3, RandomKind::spd, rng);
  std::vector<std::tuple<index_t, index_t, double>> entries;  // (row, col) of K, row >= col
  for (index_t j = 0; j < n1; ++j)
    for (index_t p = h.offsets[j]; p < h.offsets[j + 1]; ++p)
      entries.emplace_back(h.indices[p], j, h.values[p]);
  // B: row k couples constraint n1 + k with variable q[k] (its own) and two random ones
  std::vector<index_t> q(n1);
  std::iota(q.begin(), q.end(), index_t{0});
  std::shuffle(q.begin(), q.end(), rng);
  std::uniform_real_distribution<double> mag(0.5, 1.5), val(-1.0, 1.0);
  std::uniform_int_distribution<index_t> col(0, std::max<index_t>(n1 - 1, 0));
  std::bernoulli_distribution sign(0.5);
  for (index_t k = 0; k < n2; ++k) {
    std::set<index_t> cols{q[k]};
    entries.emplace_back(n1 + k, q[k], (sign(rng) ? 1.0 : -1.0) * mag(rng));
    for (int t = 0; t < 2; ++t) {
      const index_t c = col(rng);
      if (cols.insert(c).second) entries.emplace_back(n1 + k, c, val(rng));
    }
  }
  // random symmetric permutation: old index i becomes where[i]
  std::vector<index_t> where(n);
  std::iota(where.begin(), where.end(), index_t{0});
  std::shuffle(where.begin(), where.end(), rng);
  std::vector<double> scale(n, 1.0);
  if (decades > 0) {
    std::uniform_real_distribution<double> e(-decades, decades);
    for (double& s : scale) s = std::pow(10.0, e(rng));
  }
  std::vector<std::vector<std::pair<index_t, double>>> cols(n);
  for (const auto& [i, j, v] : entries) {
    const index_t pi = where[i], pj = where[j];
    cols[std::min(pi, pj)].push_back({std::max(pi, pj), v * scale[pi] * scale[pj]});
  }
  SparseMatrix a;
  a.n_rows = a.n_cols = n;
  a.storage = Storage::lower;
  a.offsets.assign(1, 0);
  for (index_t j = 0; j < n; ++j) {
    std::sort(cols[j].begin(), cols[j].end());
    for (const auto& [i, v] : cols[j]) {
      a.indices.push_back(i);
      a.values.push_back(v);
    }
    a.offsets.push_back(static_cast<index_t>(a.indices.size()));
  }
  if (is_constraint) {
    is_constraint->assign(n, 0);
    for (index_t k = 0; k < n2; ++k) (*is_constraint)[where[n1 + k]] = 1;
  }
  return a;
}

StaleKkt stale_kkt(index_t n, std::mt19937_64& rng, double decades) {
  std::vector<char> constraint;
  const SparseMatrix k = random_kkt(n, rng, decades, &constraint);
  // the constraint rows' diagonal (lower storage: it leads its column) set to `diag`
  auto with_diagonal = [&](double diag) {
    SparseMatrix a;
    a.n_rows = a.n_cols = n;
    a.storage = Storage::lower;
    a.offsets.assign(1, 0);
    for (index_t j = 0; j < n; ++j) {
      if (constraint[j]) {
        a.indices.push_back(j);
        a.values.push_back(diag);
      }
      for (index_t p = k.offsets[j]; p < k.offsets[j + 1]; ++p) {
        a.indices.push_back(k.indices[p]);
        a.values.push_back(k.values[p]);
      }
      a.offsets.push_back(static_cast<index_t>(a.indices.size()));
    }
    return a;
  };
  StaleKkt r;
  r.analyzed = with_diagonal(20.0);
  r.kkt = with_diagonal(0.0);
  r.constraints = n / 3;
  return r;
}

std::vector<double> to_dense(const SparseMatrix& a) {
  std::vector<double> d(static_cast<size_t>(a.n_rows * a.n_cols), 0.0);
  for (index_t j = 0; j < a.n_major(); ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      index_t r = a.layout == Layout::csc ? a.indices[p] : j;
      index_t c = a.layout == Layout::csc ? j : a.indices[p];
      double v = a.values.empty() ? 1.0 : a.values[p];
      d[r + c * a.n_rows] += v;
      if (a.storage != Storage::full && r != c) d[c + r * a.n_rows] += v;
    }
  return d;
}

bool dense_solve(std::vector<double> a, index_t n, std::vector<double>& b, index_t nrhs) {
  if (n == 0) return true;
  int ni = static_cast<int>(n), nr = static_cast<int>(nrhs), info = 0;
  std::vector<int> ipiv(n);
  dgesv_(&ni, &nr, a.data(), &ni, ipiv.data(), b.data(), &ni, &info);
  return info == 0;
}

void dense_logdet(const SparseMatrix& a, double* logdet, int* sign) {
  std::vector<double> d = to_dense(a);
  const int n = static_cast<int>(a.n_rows);
  std::vector<int> ipiv(std::max(n, 1));
  int info = 0;
  dgetrf_(&n, &n, d.data(), &n, ipiv.data(), &info);
  *logdet = 0;
  *sign = 1;
  for (int i = 0; i < n; ++i) {
    const double u = d[i + static_cast<std::size_t>(i) * n];
    *logdet += std::log(std::abs(u));
    if (u < 0) *sign = -*sign;
    if (u == 0) *sign = 0;
    if (ipiv[i] != i + 1) *sign = -*sign;
  }
}

void zero_some_diagonal(SparseMatrix& a, int one_in, std::mt19937_64& rng) {
  std::uniform_int_distribution<int> coin(0, std::max(one_in, 1) - 1);
  for (index_t j = 0; j < a.n_cols; ++j)
    if (coin(rng) == 0)
      for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
        if (a.indices[p] == j) a.values[p] = 0.0;
}

double condition_inf(const SparseMatrix& a) {
  const index_t n = a.n_cols;
  if (n == 0) return 0.0;
  std::vector<double> d = to_dense(a);  // column-major n × n, symmetric storage expanded
  double norm = 0;
  for (index_t i = 0; i < n; ++i) {
    double r = 0;
    for (index_t j = 0; j < n; ++j) r += std::abs(d[i + static_cast<std::size_t>(j) * n]);
    norm = std::max(norm, r);
  }
  const int in = static_cast<int>(n);
  std::vector<int> ipiv(n), iwork(n);
  std::vector<double> work(4 * static_cast<std::size_t>(n));
  int info = 0;
  dgetrf_(&in, &in, d.data(), &in, ipiv.data(), &info);
  if (info != 0) return std::numeric_limits<double>::infinity();
  const char inf_norm = 'I';
  double rcond = 0;
  dgecon_(&inf_norm, &in, d.data(), &in, &norm, &rcond, work.data(), iwork.data(), &info);
  return rcond > 0 ? 1.0 / rcond : std::numeric_limits<double>::infinity();
}

double backward_error(const SparseMatrix& a, const double* x, const double* b) {
  const index_t n = a.n_rows;
  std::vector<double> ax(n);
  multiply(a, x, ax.data());
  std::vector<double> rowabs(n, 0.0);  // ‖A‖∞ from the entries, symmetric storage expanded
  for (index_t j = 0; j < a.n_major(); ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      index_t r = a.layout == Layout::csc ? a.indices[p] : j;
      index_t c = a.layout == Layout::csc ? j : a.indices[p];
      double v = std::abs(a.values.empty() ? 1.0 : a.values[p]);
      rowabs[r] += v;
      if (a.storage != Storage::full && r != c) rowabs[c] += v;
    }
  double anorm = 0, xnorm = 0, bnorm = 0, rnorm = 0;
  for (index_t i = 0; i < n; ++i) {
    anorm = std::max(anorm, rowabs[i]);
    rnorm = std::max(rnorm, std::abs(b[i] - ax[i]));
    bnorm = std::max(bnorm, std::abs(b[i]));
  }
  for (index_t j = 0; j < a.n_cols; ++j) xnorm = std::max(xnorm, std::abs(x[j]));
  const double den = anorm * xnorm + bnorm;
  return den == 0 ? rnorm : rnorm / den;
}

double relative_difference(const std::vector<double>& x, const std::vector<double>& y) {
  double num = 0, den = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    // a NaN on one side only is as far as it gets (std::max would drop it)
    if (std::isnan(x[i]) != std::isnan(y[i])) return std::numeric_limits<double>::infinity();
    num = std::max(num, std::abs(x[i] - y[i]));
    den = std::max(den, std::abs(y[i]));
  }
  return den == 0 ? num : num / den;
}

namespace {

// A single-threaded CPU executor without its whole-tree traversal (factor_tree): the
// driver then runs the level schedule batch by batch (level_schedule_factor).
class LevelScheduleExecutor final : public numeric::Executor {
 public:
  const char* name() const override { return "level schedule"; }
  void begin(const numeric::FactorContext& c) override { inner_->begin(c); }
  void begin_part(const numeric::FactorContext& c) override { inner_->begin_part(c); }
  void factor_batch(const numeric::FactorContext& c, const BatchInfo& b) override {
    inner_->factor_batch(c, b);
  }
  void end_part(const numeric::FactorContext& c) override { inner_->end_part(c); }
  std::size_t export_cb(const numeric::FactorContext& c, numeric::CbTransfer& t) override {
    return inner_->export_cb(c, t);
  }
  std::size_t import_cb(const numeric::FactorContext& c, const numeric::CbTransfer& t) override {
    return inner_->import_cb(c, t);
  }
  void end(const numeric::FactorContext& c) override { inner_->end(c); }

 private:
  std::unique_ptr<numeric::Executor> inner_ = numeric::make_cpu_executor(1);
};

}  // namespace

numeric::NumericFactor level_schedule_factor(const Analysis& an, const std::vector<double>& v,
                                             MatrixType type, double pivot) {
  numeric::NumericFactor f;
  std::vector<double> arena;
  LevelScheduleExecutor one;
  numeric::factorize(an, v, type, pivot, one, f, arena);
  return f;
}

std::vector<double> scaled_values(const Analysis& an, const SparseMatrix& a, double* pivot) {
  const SparseMatrix c = canonical_values(an, a);
  std::vector<double> v(c.nnz());
  double mx = 0;
  for (index_t j = 0; j < c.n_cols; ++j)
    for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
      const index_t i = c.indices[p];
      v[p] = an.row_scaling.empty() ? c.values[p]
                                    : c.values[p] * an.row_scaling[i] * an.col_scaling[j];
      mx = std::max(mx, std::abs(v[p]));
    }
  *pivot = 1e-8 * std::max(mx, 1.0);
  return v;
}

void sleep_if(bool slow, double seconds) {
  if (slow) std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
}

}  // namespace strata::test
