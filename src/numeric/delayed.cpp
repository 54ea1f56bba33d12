// strata — multifrontal LU with delayed pivots (see delayed.hpp).
//
// Front f of the assembly tree, with msym symbolic rows (its ksym pivots first) and d rows
// and columns delayed by its children, is assembled as an m×m dense matrix, m = d + msym:
//
//   rows    = the children's delayed rows (in child order), then f's symbolic rows,
//   columns = the children's delayed columns (in child order), then f's symbolic rows,
//
// with its first p = d + ksym rows and columns fully summed. The original entries come
// from the analysis's assembly map (made for the msym×msym symbolic front: shifted by d),
// and each child's contribution block is added at the positions of its row and column
// lists (a delayed variable's row and column hold nothing from other children: it is
// coupled only to what was in its own front). The partial factorization
// (cpu::factor_front_lu_delayed) eliminates npiv ≤ p pivots; the rest of the fully summed
// rows and columns lead the contribution block pushed for the parent. A front without a
// parent (a root) may not delay: what is left there is singular to working precision and
// gets static pivots.
//
// The stack of contribution blocks: fronts are numbered in postorder, so when f is
// assembled its children's blocks are the top entries of the stack, in child order; they
// are popped before f's own block is pushed. Its peak is the same quantity as the
// fixed-layout arena's (Liu's stack depth), plus the delayed rows and columns.
#include "numeric/delayed.hpp"

#include <algorithm>
#include <cstring>
#include <new>
#include <string>

#include "core/alloc.hpp"
#include "strata/errors.hpp"

namespace strata::numeric {
namespace {

// Parity (+1 / −1) of a permutation given as a sequence of the indices 0..n-1.
int parity(const std::vector<index_t>& seq, std::vector<char>& seen) {
  const std::size_t n = seq.size();
  seen.assign(n, 0);
  int sign = 1;
  for (std::size_t i = 0; i < n; ++i) {
    if (seen[i]) continue;
    std::size_t len = 0;
    for (std::size_t j = i; !seen[j]; j = static_cast<std::size_t>(seq[j])) {
      seen[j] = 1;
      ++len;
    }
    if (len % 2 == 0) sign = -sign;
  }
  return sign;
}

template <class T>
void grow(std::vector<T>& v, std::size_t size, const char* what) {
  if (size <= v.size()) return;
  try {
    v.resize(std::max(size, v.size() + v.size() / 2));
  } catch (const std::bad_alloc&) {
    throw OutOfMemory(size * sizeof(T), std::string("factorize (delayed pivots): ") + what);
  }
}

}  // namespace

void factorize_delayed(const Analysis& an, const double* vals, MatrixType type, double threshold,
                       double static_pivot, DelayedFactor& F, DelayedWorkspace& W) {
  if (type != MatrixType::general)
    throw NotSupported("delayed pivoting is implemented for LU (general matrices) only");
  if (!(threshold > 0 && threshold <= 1))
    throw InvalidInput("the pivot threshold must be in (0, 1], got " + std::to_string(threshold));
  const auto& t = an.tree;
  const index_t nf = t.n_fronts();
  F.type = type;
  F.valid = false;
  F.m.assign(nf, 0);
  F.k.assign(nf, 0);
  F.index_offset.assign(nf + 1, 0);
  F.value_offset.assign(nf + 1, 0);
  F.front_stats.assign(nf, cpu::PivotStats{});
  F.delayed = F.fronts_delaying = F.largest_front = 0;
  std::size_t nidx = 0, nval = 0;
  grow(F.rows, t.rows.size(), "row lists");
  grow(F.cols, t.rows.size(), "column lists");
  grow(F.values, an.factor_layout.total, "factor values");
  W.row_pos.assign(an.n, -1);
  W.col_pos.assign(an.n, -1);
  W.blocks.clear();
  std::size_t stack_top = 0, index_top = 0;
  const auto& am = an.assembly;
  cpu::DelayPolicy policy;
  policy.threshold = threshold;
  policy.tiny = static_pivot;
  policy.static_pivot = static_pivot;

  for (index_t f = 0; f < nf; ++f) {
    const index_t msym = t.n_rows(f), ksym = t.n_pivots(f);
    const index_t* sym = t.rows_of(f);
    const index_t nchild = t.child_offsets[f + 1] - t.child_offsets[f];
    const std::size_t first_block = W.blocks.size() - static_cast<std::size_t>(nchild);
    index_t d = 0;
    for (std::size_t b = first_block; b < W.blocks.size(); ++b) d += W.blocks[b].delayed;
    const index_t m = d + msym, p = d + ksym;
    F.largest_front = std::max(F.largest_front, m);

    // the front's row and column lists
    grow(F.rows, nidx + m, "row lists");
    grow(F.cols, nidx + m, "column lists");
    index_t* R = F.rows.data() + nidx;
    index_t* C = F.cols.data() + nidx;
    index_t at = 0;
    for (std::size_t b = first_block; b < W.blocks.size(); ++b) {
      const auto& blk = W.blocks[b];
      const index_t* br = W.stack_index.data() + blk.indices;
      for (index_t i = 0; i < blk.delayed; ++i, ++at) {
        R[at] = br[i];
        C[at] = br[blk.size + i];
      }
    }
    for (index_t i = 0; i < msym; ++i) R[d + i] = C[d + i] = sym[i];
    for (index_t i = 0; i < m; ++i) {
      W.row_pos[R[i]] = i;
      W.col_pos[C[i]] = i;
    }

    // assemble: original entries (shifted past the delayed rows and columns), children
    const std::size_t mm = static_cast<std::size_t>(m) * m;
    grow(W.front, mm, "front workspace");
    double* A = W.front.data();
    std::fill(A, A + mm, 0.0);
    for (index_t e = am.entry_offsets[f]; e < am.entry_offsets[f + 1]; ++e) {
      const index_t dst = am.entry_dst[e];
      const index_t i = dst % msym, j = dst / msym;
      A[(d + i) + static_cast<std::size_t>(d + j) * m] += vals[am.entry_src[e]];
    }
    for (std::size_t b = first_block; b < W.blocks.size(); ++b) {
      const auto& blk = W.blocks[b];
      const index_t s = blk.size;
      const index_t* br = W.stack_index.data() + blk.indices;
      const index_t* bc = br + s;
      const double* v = W.stack.data() + blk.values;
      for (index_t c = 0; c < s; ++c) {
        double* dst = A + static_cast<std::size_t>(W.col_pos[bc[c]]) * m;
        const double* src = v + static_cast<std::size_t>(c) * s;
        for (index_t r = 0; r < s; ++r) dst[W.row_pos[br[r]]] += src[r];
      }
    }
    if (nchild > 0) {  // pop the children's blocks
      stack_top = W.blocks[first_block].values;
      index_top = W.blocks[first_block].indices;
      W.blocks.resize(first_block);
    }

    // factor
    grow(W.row_perm, static_cast<std::size_t>(p), "front permutation");
    grow(W.col_perm, static_cast<std::size_t>(p), "front permutation");
    policy.may_delay = t.parent[f] >= 0;
    const index_t npiv = cpu::factor_front_lu_delayed(A, m, p, m, policy, W.row_perm.data(),
                                                      W.col_perm.data(), F.front_stats[f]);
    for (index_t i = 0; i < m; ++i) {
      W.row_pos[R[i]] = -1;
      W.col_pos[C[i]] = -1;
    }
    {  // the permuted lists (positions p..m are not moved)
      std::vector<index_t>& tmp = W.stack_index;  // scratch past its top
      grow(tmp, index_top + 2 * static_cast<std::size_t>(p), "front permutation");
      index_t* r0 = tmp.data() + index_top;
      index_t* c0 = r0 + p;
      for (index_t i = 0; i < p; ++i) {
        r0[i] = R[W.row_perm[i]];
        c0[i] = C[W.col_perm[i]];
      }
      std::copy(r0, r0 + p, R);
      std::copy(c0, c0 + p, C);
    }

    // store L (m × npiv) and U12 (npiv × (m − npiv))
    F.m[f] = m;
    F.k[f] = npiv;
    const std::size_t lsize = static_cast<std::size_t>(m) * npiv;
    const std::size_t usize = static_cast<std::size_t>(npiv) * (m - npiv);
    grow(F.values, nval + lsize + usize, "factor values");
    double* L = F.values.data() + nval;
    std::memcpy(L, A, sizeof(double) * lsize);
    double* U = L + lsize;
    for (index_t j = npiv; j < m; ++j)
      std::memcpy(U + static_cast<std::size_t>(j - npiv) * npiv,
                  A + static_cast<std::size_t>(j) * m, sizeof(double) * npiv);
    nidx += m;
    nval += lsize + usize;
    F.index_offset[f + 1] = nidx;
    F.value_offset[f + 1] = nval;
    const index_t delays = p - npiv;
    F.delayed += delays;
    if (delays > 0) ++F.fronts_delaying;

    // push the contribution block (delayed rows and columns first)
    if (t.parent[f] >= 0) {
      DelayedWorkspace::Block blk;
      blk.size = m - npiv;
      blk.delayed = delays;
      blk.values = stack_top;
      blk.indices = index_top;
      const std::size_t s = static_cast<std::size_t>(blk.size);
      grow(W.stack, stack_top + s * s, "contribution blocks");
      grow(W.stack_index, index_top + 2 * s, "contribution blocks");
      double* v = W.stack.data() + stack_top;
      for (std::size_t c = 0; c < s; ++c)
        std::memcpy(v + c * s, A + (npiv + c) * m + npiv, sizeof(double) * s);
      std::copy(R + npiv, R + m, W.stack_index.data() + index_top);
      std::copy(C + npiv, C + m, W.stack_index.data() + index_top + s);
      stack_top += s * s;
      index_top += 2 * s;
      W.blocks.push_back(blk);
    }
  }
  if (!W.blocks.empty())
    throw InvalidState("internal: delayed factorization left contribution blocks unconsumed");
  F.valid = true;
}

void solve_delayed(const Analysis& an, const DelayedFactor& F, double* b, index_t nrhs) {
  const index_t n = an.n, nf = static_cast<index_t>(F.m.size());
  std::vector<double> x(static_cast<std::size_t>(n) * nrhs, 0.0), w;
  for (index_t r = 0; r < nrhs; ++r) {
    double* z = b + static_cast<std::size_t>(r) * n;
    double* xr = x.data() + static_cast<std::size_t>(r) * n;
    // forward: L y = z over the row pivot sequence
    for (index_t f = 0; f < nf; ++f) {
      const index_t m = F.m[f], k = F.k[f];
      const index_t* R = F.rows.data() + F.index_offset[f];
      const double* L = F.values.data() + F.value_offset[f];
      w.resize(k);
      for (index_t i = 0; i < k; ++i) w[i] = z[R[i]];
      for (index_t j = 0; j < k; ++j) {
        const double wj = w[j];
        if (wj == 0.0) continue;
        const double* l = L + static_cast<std::size_t>(j) * m;
        for (index_t i = j + 1; i < k; ++i) w[i] -= l[i] * wj;
        for (index_t i = k; i < m; ++i) z[R[i]] -= l[i] * wj;
      }
      for (index_t i = 0; i < k; ++i) z[R[i]] = w[i];
    }
    // backward: U x = y over the column pivot sequence
    for (index_t f = nf - 1; f >= 0; --f) {
      const index_t m = F.m[f], k = F.k[f];
      const index_t* R = F.rows.data() + F.index_offset[f];
      const index_t* C = F.cols.data() + F.index_offset[f];
      const double* L = F.values.data() + F.value_offset[f];
      const double* U = L + static_cast<std::size_t>(m) * k;
      w.resize(k);
      for (index_t i = 0; i < k; ++i) w[i] = z[R[i]];
      for (index_t j = k; j < m; ++j) {
        const double xj = xr[C[j]];
        if (xj == 0.0) continue;
        const double* u = U + static_cast<std::size_t>(j - k) * k;
        for (index_t i = 0; i < k; ++i) w[i] -= u[i] * xj;
      }
      for (index_t j = k - 1; j >= 0; --j) {
        const double* col = L + static_cast<std::size_t>(j) * m;
        const double d = col[j];
        w[j] = d != 0.0 ? w[j] / d : 0.0;
        const double wj = w[j];
        for (index_t i = 0; i < j; ++i) w[i] -= col[i] * wj;
      }
      for (index_t i = 0; i < k; ++i) xr[C[i]] = w[i];
    }
  }
  std::copy(x.begin(), x.end(), b);
}

int delayed_determinant_sign(const Analysis& an, const DelayedFactor& F) {
  int sign = 1;
  for (const auto& s : F.front_stats) sign *= s.det_sign;
  if (sign == 0) return 0;
  std::vector<index_t> rseq, cseq;
  rseq.reserve(an.n);
  cseq.reserve(an.n);
  for (std::size_t f = 0; f < F.m.size(); ++f)
    for (index_t i = 0; i < F.k[f]; ++i) {
      rseq.push_back(F.rows[F.index_offset[f] + i]);
      cseq.push_back(F.cols[F.index_offset[f] + i]);
    }
  std::vector<char> seen;
  return sign * parity(rseq, seen) * parity(cseq, seen);
}

}  // namespace strata::numeric
