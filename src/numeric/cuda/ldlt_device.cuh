// strata — the device code of the CUDA LDLᵀ kernels (kernels_ldlt.cu), in a header of its own
// so that the CPU tests can also compile it for the host and run it with one OS thread per
// CUDA thread (tests/unit/test_ldlt_kernel_emulation.cpp): the index arithmetic, the
// pivoting decisions and the barrier placement are then checked in CI, without a GPU,
// against the CPU kernel. Only kernels_ldlt.cu and that test include this file. It uses
// nothing from CUDA but threadIdx/blockDim, __syncthreads, __shared__, __device__, fabs,
// isfinite, __dmul_rn and __dadd_rn (the test defines host stand-ins for them).
//
// Algorithms: see the header comment of kernels_ldlt.cu.
//
// Every thread of a block runs every __syncthreads(): all branches around them depend
// only on values read from shared memory after a barrier (uniform across the block), and
// the loops around them run the same trip count in every thread.
#pragma once

#include <cstdint>

// Internal linkage (the unnamed namespace): nvcc emits a host stub for every __device__
// function, which would otherwise be a strong external symbol of libstrata and win over
// the host build of these functions in the emulation test (which then called exit(1)).
namespace strata::cuda::ldlt_device {
namespace {

constexpr int kLdltThreads = 256;  // threads per block: a power of two (the reductions halve it)
constexpr std::int64_t kLdltPanel = 64;  // panel width of large fronts (+1 for a 2×2 at its end)
constexpr double kBkAlpha = 0.6403882032022076;  // (1 + √17)/8

struct Reduction {
  double val[kLdltThreads];
  std::int64_t idx[kLdltThreads];
};

// Block-wide max of |get(i)| over i in [r0, r1), i ≠ skip; the first (smallest) index
// among equal maxima, NaNs ignored, as the CPU's strict `>` scan. Returns the max (0 for
// an empty range) and its index in *arg (-1 when the max is 0 or the range empty). Every
// thread gets the result.
template <class Get>
__device__ double block_max_abs(std::int64_t r0, std::int64_t r1, std::int64_t skip, Get get,
                                Reduction& red, std::int64_t* arg) {
  double best = 0.0;
  std::int64_t at = -1;
  for (std::int64_t i = r0 + threadIdx.x; i < r1; i += blockDim.x) {
    if (i == skip) continue;
    const double v = fabs(get(i));
    if (v > best) {
      best = v;
      at = i;
    }
  }
  red.val[threadIdx.x] = best;
  red.idx[threadIdx.x] = at;
  __syncthreads();
  for (int stride = blockDim.x / 2; stride > 0; stride /= 2) {
    if (threadIdx.x < stride) {
      const double o = red.val[threadIdx.x + stride];
      const std::int64_t oi = red.idx[threadIdx.x + stride];
      const double c = red.val[threadIdx.x];
      const std::int64_t ci = red.idx[threadIdx.x];
      if (o > c || (o == c && oi >= 0 && (ci < 0 || oi < ci))) {
        red.val[threadIdx.x] = o;
        red.idx[threadIdx.x] = oi;
      }
    }
    __syncthreads();
  }
  const double r = red.val[0];
  *arg = red.idx[0];
  __syncthreads();  // the buffer may be reused at once
  return r;
}

// The decisions of one pivot step, made by thread 0 and read by all after a barrier.
struct Step {
  double colmax;
  std::int64_t imax;
  int need_row;  // the Bunch–Kaufman tests need the candidate column imax
  int kstep;     // 1 or 2
  std::int64_t kp;
  int take_imax;         // 1×1 pivot at imax (large-front kernel: its column replaces wc)
  double inv;            // 1×1: 1/d (0 for a zero pivot)
  double i11, i21, i22;  // 2×2: D⁻¹
};

// Static pivoting of one 1×1 pivot (the CPU's perturb()).
__device__ double perturb(double d, double sp, std::int64_t* perturbed) {
  if (fabs(d) < sp) {
    ++*perturbed;
    return d < 0 ? -sp : sp;
  }
  return d;
}

// First Bunch–Kaufman test, on thread 0: is the candidate column imax needed?
__device__ void first_test(Step& st, double absakk, double sp) {
  const double big = absakk < st.colmax ? st.colmax : absakk;  // std::max(absakk, colmax)
  st.need_row = st.colmax > 0 && !(big < sp) && !(absakk >= kBkAlpha * st.colmax);
}

// The rest of the tests, on thread 0, given rowmax, the pivot candidates' entries
// a = A(kk,kk), b = A(imax,kk), c = A(imax,imax) (all updated). Sets kstep/kp/take_imax and,
// for a 2×2 pivot, D⁻¹ computed relative to b as the CPU's pivot_2x2 does.
__device__ void second_test(Step& st, double a, double b, double c, double rowmax) {
  const double absakk = fabs(a);
  if (absakk >= kBkAlpha * st.colmax * (st.colmax / rowmax)) return;  // 1×1 at kk
  if (fabs(c) >= kBkAlpha * rowmax) {
    st.kp = st.imax;
    st.take_imax = 1;
    return;
  }
  const double p = a / b, q = c / b;
  const double g = __dadd_rn(__dmul_rn(p, q), -1.0);  // no FMA: the CPU's rounding
  if (!(fabs(g) >= 0.25 && isfinite(g))) return;      // defensive: 1×1 at kk
  const double e = 1.0 / __dmul_rn(b, g);
  st.kstep = 2;
  st.kp = st.imax;
  st.i11 = e * q;
  st.i21 = -e;
  st.i22 = e * p;
}

// Symmetric interchange of indices ks < kp of the lower m×m front: A(ks,ks) ↔ A(kp,kp),
// A(i,ks) ↔ A(kp,i) for ks < i < kp, A(i,ks) ↔ A(i,kp) for i > kp, and rows ks, kp of
// columns [0, col_end). The four sets are disjoint, so all threads swap at once.
__device__ void symmetric_swap(double* F, std::int64_t m, std::int64_t ks, std::int64_t kp,
                               std::int64_t col_end) {
  const std::int64_t n_mid = kp - ks - 1, n_low = m - kp - 1;
  const std::int64_t total = 1 + n_mid + n_low + col_end;
  for (std::int64_t x = threadIdx.x; x < total; x += blockDim.x) {
    double *a, *b;
    if (x == 0) {
      a = F + ks * m + ks;
      b = F + kp * m + kp;
    } else if (x <= n_mid) {
      const std::int64_t i = ks + x;  // ks < i < kp
      a = F + ks * m + i;
      b = F + i * m + kp;
    } else if (x <= n_mid + n_low) {
      const std::int64_t i = kp + (x - n_mid);  // kp < i < m
      a = F + ks * m + i;
      b = F + kp * m + i;
    } else {
      const std::int64_t j = x - 1 - n_mid - n_low;  // 0 <= j < col_end
      a = F + j * m + ks;
      b = F + j * m + kp;
    }
    const double tmp = *a;
    *a = *b;
    *b = tmp;
  }
}

// ---- small fronts: right-looking over the whole front --------------------------------------

__device__ void ldlt_small_front(double* F, std::int64_t m, std::int64_t k, double sp,
                                 std::int64_t* perm, int* psize, std::int64_t* perturbed) {
  __shared__ Reduction red;
  __shared__ Step st;
  for (std::int64_t r = threadIdx.x; r < k; r += blockDim.x) perm[r] = r;
  if (threadIdx.x == 0) *perturbed = 0;
  __syncthreads();
  std::int64_t kk = 0;
  while (kk < k) {
    double* colk = F + kk * m;
    std::int64_t imax;
    const double colmax = block_max_abs(
        kk + 1, k, -1, [&](std::int64_t i) { return colk[i]; }, red, &imax);
    if (threadIdx.x == 0) {
      st.colmax = colmax;
      st.imax = imax;
      st.kstep = 1;
      st.kp = kk;
      st.take_imax = 0;
      first_test(st, fabs(colk[kk]), sp);
    }
    __syncthreads();
    if (st.need_row) {
      const std::int64_t im = st.imax;
      std::int64_t unused;
      // row imax of the trailing matrix within the pivot block: A(imax, j) for kk <= j <
      // imax (lower: F[j*m + imax]), A(i, imax) for imax < i < k
      const double rowmax = block_max_abs(
          kk, k, im, [&](std::int64_t i) { return i < im ? F[i * m + im] : F[im * m + i]; }, red,
          &unused);
      if (threadIdx.x == 0) second_test(st, colk[kk], colk[im], F[im * m + im], rowmax);
      __syncthreads();
    }
    const int kstep = st.kstep;
    const std::int64_t ks = kk + kstep - 1, kp = st.kp;
    if (kp != ks) {
      symmetric_swap(F, m, ks, kp, ks);
      if (threadIdx.x == 0) {
        const std::int64_t tp = perm[ks];
        perm[ks] = perm[kp];
        perm[kp] = tp;
      }
      __syncthreads();
    }
    const std::int64_t rows = m - kk - kstep;  // trailing order
    if (kstep == 1) {
      if (threadIdx.x == 0) {
        const double d = perturb(colk[kk], sp, perturbed);
        colk[kk] = d;
        st.inv = d != 0 ? 1.0 / d : 0.0;  // zero pivot: pseudo-inverse
        psize[kk] = 1;
      }
      __syncthreads();
      const double inv = st.inv;
      // F(i, j) −= w_i (w_j / d) for kk < j <= i < m, w = column kk before scaling
      for (std::int64_t x = threadIdx.x; x < rows * rows; x += blockDim.x) {
        const std::int64_t i = kk + 1 + x % rows, j = kk + 1 + x / rows;
        if (i >= j) F[j * m + i] -= colk[i] * (colk[j] * inv);
      }
      __syncthreads();
      for (std::int64_t i = kk + 1 + threadIdx.x; i < m; i += blockDim.x) colk[i] *= inv;
    } else {
      if (threadIdx.x == 0) psize[kk] = psize[kk + 1] = 2;
      const double i11 = st.i11, i21 = st.i21, i22 = st.i22;
      double* col2 = colk + m;
      for (std::int64_t x = threadIdx.x; x < rows * rows; x += blockDim.x) {
        const std::int64_t i = kk + 2 + x % rows, j = kk + 2 + x / rows;
        if (i >= j) {
          const double l1 = i11 * colk[j] + i21 * col2[j];
          const double l2 = i21 * colk[j] + i22 * col2[j];
          F[j * m + i] -= colk[i] * l1 + col2[i] * l2;
        }
      }
      __syncthreads();
      for (std::int64_t i = kk + 2 + threadIdx.x; i < m; i += blockDim.x) {
        const double a1 = colk[i], a2 = col2[i];
        colk[i] = i11 * a1 + i21 * a2;
        col2[i] = i21 * a1 + i22 * a2;
      }
    }
    __syncthreads();
    kk += kstep;
  }
}

// ---- large fronts: one panel, left-looking inside it ---------------------------------------

// Factors the panel starting at column j0 of the m×m front F (k fully summed columns),
// whose columns are up to date with every earlier panel. W (m × (kLdltPanel+1), leading
// dimension m, rows indexed like F's) receives W = L·D of the panel's columns; *end the
// column after the panel. perm, psize, perturbed: the front's (initialized at j0 = 0).
__device__ void ldlt_panel(double* F, std::int64_t m, std::int64_t k, std::int64_t j0, double sp,
                           double* W, std::int64_t* perm, int* psize, std::int64_t* perturbed,
                           std::int64_t* end) {
  __shared__ Reduction red;
  __shared__ Step st;
  if (j0 == 0) {
    for (std::int64_t r = threadIdx.x; r < k; r += blockDim.x) perm[r] = r;
    if (threadIdx.x == 0) *perturbed = 0;
  }
  __syncthreads();
  const bool last = k - j0 <= kLdltPanel;
  std::int64_t kk = j0;
  while (kk < k && (last || kk - j0 < kLdltPanel)) {
    const std::int64_t c = kk - j0;  // panel column of kk (and W column)
    double* wc = W + c * m;
    // column kk brought up to date: wc = F(kk:m, kk) − L(kk:m, panel) W(kk, panel)ᵀ
    for (std::int64_t i = kk + threadIdx.x; i < m; i += blockDim.x) {
      double v = F[kk * m + i];
      for (std::int64_t cc = 0; cc < c; ++cc) v -= F[(j0 + cc) * m + i] * W[cc * m + kk];
      wc[i] = v;
    }
    __syncthreads();
    std::int64_t imax;
    const double colmax = block_max_abs(
        kk + 1, k, -1, [&](std::int64_t i) { return wc[i]; }, red, &imax);
    if (threadIdx.x == 0) {
      st.colmax = colmax;
      st.imax = imax;
      st.kstep = 1;
      st.kp = kk;
      st.take_imax = 0;
      first_test(st, fabs(wc[kk]), sp);
    }
    __syncthreads();
    double* wn = wc + m;  // W column c+1: the candidate column imax, up to date
    if (st.need_row) {
      const std::int64_t im = st.imax;
      for (std::int64_t i = kk + threadIdx.x; i < m; i += blockDim.x) {
        double v = i < im ? F[i * m + im] : F[im * m + i];  // A(imax, i) / A(i, imax)
        for (std::int64_t cc = 0; cc < c; ++cc) v -= F[(j0 + cc) * m + i] * W[cc * m + im];
        wn[i] = v;
      }
      __syncthreads();
      std::int64_t unused;
      const double rowmax = block_max_abs(
          kk, k, im, [&](std::int64_t i) { return wn[i]; }, red, &unused);
      if (threadIdx.x == 0) second_test(st, wc[kk], wc[im], wn[im], rowmax);
      __syncthreads();
      if (st.take_imax) {
        for (std::int64_t i = kk + threadIdx.x; i < m; i += blockDim.x) wc[i] = wn[i];
        __syncthreads();
      }
    }
    const int kstep = st.kstep;
    const std::int64_t ks = kk + kstep - 1, kp = st.kp;
    if (kp != ks) {
      // the not yet updated trailing part (column kk is rewritten below from wc) and rows
      // ks, kp of the finished columns of L (earlier panels and this one) ...
      symmetric_swap(F, m, ks, kp, kk);
      // ... and of W's columns so far (wc, and wn for a 2×2 pivot)
      for (std::int64_t cc = threadIdx.x; cc < c + kstep; cc += blockDim.x) {
        const double tmp = W[cc * m + ks];
        W[cc * m + ks] = W[cc * m + kp];
        W[cc * m + kp] = tmp;
      }
      if (threadIdx.x == 0) {
        const std::int64_t tp = perm[ks];
        perm[ks] = perm[kp];
        perm[kp] = tp;
      }
      __syncthreads();
    }
    double* colk = F + kk * m;
    if (kstep == 1) {
      if (threadIdx.x == 0) {
        const double d = perturb(wc[kk], sp, perturbed);
        wc[kk] = d;
        colk[kk] = d;
        st.inv = d != 0 ? 1.0 / d : 0.0;  // zero pivot: pseudo-inverse
        psize[kk] = 1;
      }
      __syncthreads();
      const double inv = st.inv;
      for (std::int64_t i = kk + 1 + threadIdx.x; i < m; i += blockDim.x) colk[i] = wc[i] * inv;
    } else {
      const double i11 = st.i11, i21 = st.i21, i22 = st.i22;
      double* col2 = colk + m;
      if (threadIdx.x == 0) {
        psize[kk] = psize[kk + 1] = 2;
        colk[kk] = wc[kk];
        colk[kk + 1] = wc[kk + 1];
        col2[kk + 1] = wn[kk + 1];
      }
      for (std::int64_t i = kk + 2 + threadIdx.x; i < m; i += blockDim.x) {
        const double w1 = wc[i], w2 = wn[i];
        colk[i] = i11 * w1 + i21 * w2;
        col2[i] = i21 * w1 + i22 * w2;
      }
    }
    __syncthreads();
    kk += kstep;
  }
  if (threadIdx.x == 0) *end = kk;
}

}  // namespace
}  // namespace strata::cuda::ldlt_device
