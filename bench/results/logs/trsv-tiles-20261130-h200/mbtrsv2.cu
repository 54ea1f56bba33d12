// throwaway microbenchmark: trsv_tiles_kernel (inverse diagonal tiles from the host) against
// cublasDtrsv
#include <cublas_v2.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "numeric/cuda/trsv_tiles.cuh"
using namespace strata::cuda::trsv_tiles;
#define CK(x)                                                       \
  do {                                                              \
    cudaError_t e = (x);                                            \
    if (e) {                                                        \
      printf("cuda %s line %d\n", cudaGetErrorString(e), __LINE__); \
      exit(1);                                                      \
    }                                                               \
  } while (0)
template <int T>
void launch(int form, int n, const double* a, long lda, double* x, const double* inv, TrsvSync s,
            cudaStream_t st) {
  const int tiles = (n + T - 1) / T;
  if (form == 0)
    trsv_tiles_kernel<TrsvForm::lower, T><<<tiles, 4 * T, 0, st>>>(n, a, lda, x, inv, s);
  if (form == 1)
    trsv_tiles_kernel<TrsvForm::upper, T><<<tiles, 4 * T, 0, st>>>(n, a, lda, x, inv, s);
  if (form == 2)
    trsv_tiles_kernel<TrsvForm::lower_transposed, T><<<tiles, 4 * T, 0, st>>>(n, a, lda, x, inv, s);
}
int main() {
  std::mt19937_64 rng(std::random_device{}());
  std::uniform_real_distribution<double> u(-1, 1);
  cublasHandle_t h;
  cublasCreate(&h);
  cudaStream_t st;
  CK(cudaStreamCreate(&st));
  cublasSetStream(h, st);
  int* dsync;
  CK(cudaMalloc(&dsync, 4 * 1024));
  CK(cudaMemset(dsync, 0, 4 * 1024));
  TrsvSync sy{dsync + 2, dsync, dsync + 1};
  double worst = 0;
  for (int T : {64, 128})
    for (int form = 0; form < 3; ++form)
      for (int unit = 0; unit < 2; ++unit)
        for (int n : {1, 2, 3, 5, 63, 64, 65, 127, 128, 129, 320, 512, 733, 1024, 2048}) {
          const long lda = n + 7;
          std::vector<double> A(lda * n), b(n);
          for (auto& v : A) v = u(rng) * 2.0 / std::sqrt((double)n + 1);
          for (int i = 0; i < n; ++i)
            A[i + i * lda] = unit ? 1.0 : (u(rng) < 0 ? -1 : 1) * (1.0 + std::abs(u(rng)));
          for (auto& v : b) v = u(rng);
          auto coef = [&](long r, long c) { return form == 2 ? A[c + r * lda] : A[r + c * lda]; };
          const bool fwd = form == 0;
          std::vector<long double> xr(b.begin(), b.end());
          if (fwd) {
            for (int r = 0; r < n; ++r) {
              long double v = xr[r];
              for (int c = 0; c < r; ++c) v -= coef(r, c) * xr[c];
              xr[r] = v / coef(r, r);
            }
          } else {
            for (int r = n - 1; r >= 0; --r) {
              long double v = xr[r];
              for (int c = r + 1; c < n; ++c) v -= coef(r, c) * xr[c];
              xr[r] = v / coef(r, r);
            }
          }
          // inverse tiles of op(A)'s diagonal blocks, column-major T x T, zero padded
          const int tiles = (n + T - 1) / T;
          std::vector<double> inv((size_t)tiles * T * T, 0.0);
          for (int t = 0; t < tiles; ++t) {
            const int base = t * T, rows = std::min(T, n - base);
            for (int j = 0; j < rows; ++j) {  // column j: solve op(A)_tt m = e_j
              std::vector<long double> m(rows, 0);
              m[j] = 1;
              if (fwd) {
                for (int r = 0; r < rows; ++r) {
                  long double v = m[r];
                  for (int c = 0; c < r; ++c) v -= coef(base + r, base + c) * m[c];
                  m[r] = v / coef(base + r, base + r);
                }
              } else {
                for (int r = rows - 1; r >= 0; --r) {
                  long double v = m[r];
                  for (int c = r + 1; c < rows; ++c) v -= coef(base + r, base + c) * m[c];
                  m[r] = v / coef(base + r, base + r);
                }
              }
              for (int r = 0; r < rows; ++r)
                inv[(size_t)t * T * T + r + (size_t)j * T] = (double)m[r];
            }
          }
          double *dA, *dx, *dy, *dinv;
          CK(cudaMalloc(&dA, 8 * A.size()));
          CK(cudaMalloc(&dx, 8 * n));
          CK(cudaMalloc(&dy, 8 * n));
          CK(cudaMalloc(&dinv, 8 * inv.size()));
          CK(cudaMemcpy(dA, A.data(), 8 * A.size(), cudaMemcpyHostToDevice));
          CK(cudaMemcpy(dinv, inv.data(), 8 * inv.size(), cudaMemcpyHostToDevice));
          CK(cudaMemcpy(dx, b.data(), 8 * n, cudaMemcpyHostToDevice));
          if (T == 64)
            launch<64>(form, n, dA, lda, dx, dinv, sy, st);
          else
            launch<128>(form, n, dA, lda, dx, dinv, sy, st);
          CK(cudaStreamSynchronize(st));
          CK(cudaGetLastError());
          std::vector<double> x(n);
          CK(cudaMemcpy(x.data(), dx, 8 * n, cudaMemcpyDeviceToHost));
          double err = 0, mag = 0;
          for (int i = 0; i < n; ++i) {
            err = std::max(err, (double)std::abs(x[i] - xr[i]));
            mag = std::max(mag, (double)std::abs(xr[i]));
          }
          const double rel = err / std::max(mag, 1e-300);
          worst = std::max(worst, rel);
          double tk = 0, tc = 0;
          if (n >= 128) {
            cudaEvent_t e0, e1;
            cudaEventCreate(&e0);
            cudaEventCreate(&e1);
            float ms;
            const int R = 200;
            for (int w = 0; w < 2; ++w) {
              CK(cudaMemcpy(dy, b.data(), 8 * n, cudaMemcpyHostToDevice));
              cudaEventRecord(e0, st);
              for (int q = 0; q < R; ++q) {
                if (T == 64)
                  launch<64>(form, n, dA, lda, dy, dinv, sy, st);
                else
                  launch<128>(form, n, dA, lda, dy, dinv, sy, st);
              }
              cudaEventRecord(e1, st);
              cudaEventSynchronize(e1);
              cudaEventElapsedTime(&ms, e0, e1);
              tk = ms * 1e3 / R;
              cudaEventRecord(e0, st);
              for (int q = 0; q < R; ++q)
                cublasDtrsv(h, form == 1 ? CUBLAS_FILL_MODE_UPPER : CUBLAS_FILL_MODE_LOWER,
                            form == 2 ? CUBLAS_OP_T : CUBLAS_OP_N,
                            unit ? CUBLAS_DIAG_UNIT : CUBLAS_DIAG_NON_UNIT, n, dA, lda, dy, 1);
              cudaEventRecord(e1, st);
              cudaEventSynchronize(e1);
              cudaEventElapsedTime(&ms, e0, e1);
              tc = ms * 1e3 / R;
            }
            CK(cudaGetLastError());
          }
          if (n >= 128 || rel > 1e-13)
            printf("T %3d form %d unit %d n %5d rel err %.2e  tiles %7.2f us  cublas %7.2f us\n", T,
                   form, unit, n, rel, tk, tc);
          cudaFree(dA);
          cudaFree(dx);
          cudaFree(dy);
          cudaFree(dinv);
        }
  printf("worst rel err %.2e\n", worst);
}
