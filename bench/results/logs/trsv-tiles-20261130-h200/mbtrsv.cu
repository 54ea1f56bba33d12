// throwaway microbenchmark: trsv_block_kernel against cublasDtrsv (correctness and time)
#include <cublas_v2.h>

#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "trsv_block_single.cuh"  // the tried single-block kernel, kept beside this file
using namespace strata::cuda::trsv_block;
#define CK(x)                                                       \
  do {                                                              \
    cudaError_t e = (x);                                            \
    if (e) {                                                        \
      printf("cuda %s line %d\n", cudaGetErrorString(e), __LINE__); \
      exit(1);                                                      \
    }                                                               \
  } while (0)
template <TrsvForm F, bool U>
void launch(int n, const double* a, long lda, double* x, cudaStream_t s) {
  trsv_block_kernel<F, U><<<1, 32 * ((n + 31) / 32), 0, s>>>(n, a, lda, x);
}
void run(int form, bool unit, int n, const double* a, long lda, double* x, cudaStream_t s) {
  if (form == 0)
    unit ? launch<TrsvForm::lower, true>(n, a, lda, x, s)
         : launch<TrsvForm::lower, false>(n, a, lda, x, s);
  if (form == 1)
    unit ? launch<TrsvForm::upper, true>(n, a, lda, x, s)
         : launch<TrsvForm::upper, false>(n, a, lda, x, s);
  if (form == 2)
    unit ? launch<TrsvForm::lower_transposed, true>(n, a, lda, x, s)
         : launch<TrsvForm::lower_transposed, false>(n, a, lda, x, s);
}
int main() {
  std::mt19937_64 rng(std::random_device{}());
  std::uniform_real_distribution<double> u(-1, 1);
  cublasHandle_t h;
  cublasCreate(&h);
  cudaStream_t s;
  CK(cudaStreamCreate(&s));
  cublasSetStream(h, s);
  double worst = 0;
  for (int form = 0; form < 3; ++form)
    for (int unit = 0; unit < 2; ++unit)
      for (int n : {1, 2, 3, 5, 15, 16, 17, 31, 32, 33, 100, 320, 512, 733, 1000, 1023, 1024}) {
        const long lda = n + 7;
        std::vector<double> A(lda * n), b(n);
        for (auto& v : A) v = u(rng) * 2.0 / std::sqrt((double)n + 1);
        for (int i = 0; i < n; ++i)
          A[i + i * lda] = (u(rng) < 0 ? -1 : 1) * (1.0 + std::abs(u(rng)));
        for (auto& v : b) v = u(rng);
        // host reference in long double
        std::vector<long double> xr(b.begin(), b.end());
        auto coef = [&](int r, int c) { return form == 2 ? A[c + r * lda] : A[r + c * lda]; };
        if (form == 0) {
          for (int r = 0; r < n; ++r) {
            long double v = xr[r];
            for (int c = 0; c < r; ++c) v -= coef(r, c) * xr[c];
            xr[r] = unit ? v : v / A[r + r * lda];
          }
        } else {
          for (int r = n - 1; r >= 0; --r) {
            long double v = xr[r];
            for (int c = r + 1; c < n; ++c) v -= coef(r, c) * xr[c];
            xr[r] = unit ? v : v / A[r + r * lda];
          }
        }
        double *dA, *dx, *dy;
        CK(cudaMalloc(&dA, 8 * A.size()));
        CK(cudaMalloc(&dx, 8 * n));
        CK(cudaMalloc(&dy, 8 * n));
        CK(cudaMemcpy(dA, A.data(), 8 * A.size(), cudaMemcpyHostToDevice));
        CK(cudaMemcpy(dx, b.data(), 8 * n, cudaMemcpyHostToDevice));
        run(form, unit, n, dA, lda, dx, s);
        CK(cudaStreamSynchronize(s));
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
        if (n >= 100) {
          cudaEvent_t e0, e1;
          cudaEventCreate(&e0);
          cudaEventCreate(&e1);
          float ms;
          const int R = 200;
          for (int w = 0; w < 2; ++w) {
            CK(cudaMemcpy(dy, b.data(), 8 * n, cudaMemcpyHostToDevice));
            cudaEventRecord(e0, s);
            for (int q = 0; q < R; ++q) run(form, unit, n, dA, lda, dy, s);
            cudaEventRecord(e1, s);
            cudaEventSynchronize(e1);
            cudaEventElapsedTime(&ms, e0, e1);
            tk = ms * 1e3 / R;
            cudaEventRecord(e0, s);
            for (int q = 0; q < R; ++q)
              cublasDtrsv(h, form == 1 ? CUBLAS_FILL_MODE_UPPER : CUBLAS_FILL_MODE_LOWER,
                          form == 2 ? CUBLAS_OP_T : CUBLAS_OP_N,
                          unit ? CUBLAS_DIAG_UNIT : CUBLAS_DIAG_NON_UNIT, n, dA, lda, dy, 1);
            cudaEventRecord(e1, s);
            cudaEventSynchronize(e1);
            cudaEventElapsedTime(&ms, e0, e1);
            tc = ms * 1e3 / R;
          }
        }
        printf("form %d unit %d n %5d rel err %.2e  block %7.2f us  cublas %7.2f us\n", form, unit,
               n, rel, tk, tc);
        cudaFree(dA);
        cudaFree(dx);
        cudaFree(dy);
      }
  printf("worst rel err %.2e\n", worst);
}
