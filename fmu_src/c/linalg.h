/*
 * linalg.h - small dense linear algebra for the C model files (C99, libm): the matrix exponential
 * by scaling and squaring with a Taylor series and Van Loan's zero-order-hold map, the same
 * algorithm as fmu_src/linalg.py (the Python runtimes'), so that both backends discretise alike.
 * Matrices are row-major double arrays; n <= LA_MAX.
 */
#ifndef LATOBS_LINALG_H
#define LATOBS_LINALG_H

#include <math.h>
#include <string.h>

#define LA_MAX 16

/* C = A B (n x n), C may not alias A or B */
static void la_matmul(int n, const double *A, const double *B, double *C)
{
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            double s = 0.0;
            for (int k = 0; k < n; k++) s += A[i * n + k] * B[k * n + j];
            C[i * n + j] = s;
        }
}

static double la_norm_inf(int rows, int cols, const double *A)
{
    double best = 0.0;
    for (int i = 0; i < rows; i++) {
        double s = 0.0;
        for (int j = 0; j < cols; j++) s += fabs(A[i * cols + j]);
        if (s > best || s != s) best = s;
    }
    return best;
}

/* E = exp(M), n x n: s = least integer >= 0 with ||M||_inf 2^-s <= 1/2; Taylor series of the
 * scaled matrix summed until ||term|| <= 1e-18 ||E|| (at most 60 terms); then squared s times.
 * Returns 0, or -1 if the norm of M is not finite or needs more than 1000 squarings (E untouched). */
static int la_expm(int n, const double *M, double *E)
{
    double X[LA_MAX * LA_MAX], T[LA_MAX * LA_MAX], W[LA_MAX * LA_MAX];
    double norm = la_norm_inf(n, n, M);
    if (!(norm <= 1e300) || n > LA_MAX) return -1;
    int s = 0;
    if (norm > 0.5) s = (int)ceil(log2(norm / 0.5));
    if (s < 0) s = 0;
    if (s > 1000) return -1;
    double scale = ldexp(1.0, -s);
    for (int i = 0; i < n * n; i++) X[i] = M[i] * scale;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) E[i * n + j] = T[i * n + j] = (i == j) ? 1.0 : 0.0;
    for (int k = 1; k < 60; k++) {
        la_matmul(n, T, X, W);
        for (int i = 0; i < n * n; i++) {
            T[i] = W[i] / k;
            E[i] += T[i];
        }
        if (la_norm_inf(n, n, T) <= 1e-18 * la_norm_inf(n, n, E)) break;
    }
    for (int q = 0; q < s; q++) {
        la_matmul(n, E, E, W);
        memcpy(E, W, sizeof(double) * (size_t)(n * n));
    }
    return 0;
}

/* Exact zero-order-hold map of x' = A x + B u over h: the top n rows [Phi | Gam] (n x (n + m),
 * row-major) of expm(h [[A, B], [0, 0]]). A n x n, B n x m, n + m <= LA_MAX. 0 ok, -1 not finite. */
static int la_zoh_map(int n, int m, const double *A, const double *B, double h, double *PhiGam)
{
    int N = n + m;
    double big[LA_MAX * LA_MAX], E[LA_MAX * LA_MAX];
    if (N > LA_MAX) return -1;
    memset(big, 0, sizeof(double) * (size_t)(N * N));
    for (int i = 0; i < n; i++) {
        for (int j = 0; j < n; j++) big[i * N + j] = h * A[i * n + j];
        for (int j = 0; j < m; j++) big[i * N + n + j] = h * B[i * m + j];
    }
    if (la_expm(N, big, E) != 0) return -1;
    for (int i = 0; i < n * N; i++)
        if (!isfinite(E[i])) return -1;
    memcpy(PhiGam, E, sizeof(double) * (size_t)(n * N));
    return 0;
}

#endif
