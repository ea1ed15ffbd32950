/* Dense linear algebra for the small systems of a step (r x r, row-major): dot products,
 * the contraction of a symmetric cubic, Cholesky, cyclic Jacobi and the Newton direction. */
#include <math.h>
#include <string.h>

#include "af_internal.h"

/* a . b over r numbers, in four interleaved partial sums (independent chains the compiler
 * can pipeline and vectorize without reassociating), added pairwise at the end. */
double af_dot(const double *a, const double *b, long r) {
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    long i = 0;
    for (; i + 4 <= r; i += 4) {
        s0 += a[i] * b[i];
        s1 += a[i + 1] * b[i + 1];
        s2 += a[i + 2] * b[i + 2];
        s3 += a[i + 3] * b[i + 3];
    }
    for (; i < r; i++) s0 += a[i] * b[i];
    return (s0 + s1) + (s2 + s3);
}

/* X[a, b] = sum_c T[a, b, c] u_c (r x r) for the symmetric T whose sorted triples a <= b <= c
 * are A (T,) in W4's row order: each sorted triple adds to the upper triangle once for each
 * distinct index it can give up to u; the lower triangle is mirrored. */
void af_contract(const double *A, const double *u, double *X, long r) {
    long a, b, c, t = 0;
    for (a = 0; a < r * r; a++) X[a] = 0.0;
    for (a = 0; a < r; a++)
        for (b = a; b < r; b++) {
            double v = A[t++], acc = v * u[b];   /* c = b */
            if (a != b) X[b * r + b] += v * u[a];
            for (c = b + 1; c < r; c++) {
                v = A[t++];
                acc += v * u[c];
                X[a * r + c] += v * u[b];
                if (a != b) X[b * r + c] += v * u[a];
            }
            X[a * r + b] += acc;
        }
    for (a = 0; a < r; a++)
        for (b = 0; b < a; b++) X[a * r + b] = X[b * r + a];
}

/* Cholesky of H (r x r) into L (lower); 0 where H is not positive definite. */
static int cholesky(const double *H, double *L, long r) {
    long i, j;
    for (i = 0; i < r; i++)
        for (j = 0; j <= i; j++) {
            double s = H[i * r + j] - af_dot(L + i * r, L + j * r, j);
            if (i == j) {
                if (!(s > 0.0)) return 0;
                L[i * r + i] = sqrt(s);
            } else {
                L[i * r + j] = s / L[j * r + j];
            }
        }
    return 1;
}

/* Eigenvalues lam and eigenvectors (columns of V) of the symmetric H by cyclic Jacobi. */
static void jacobi(const double *H, double *V, double *lam, double *B, long r) {
    long i, j, k, sweep;
    memcpy(B, H, (size_t)(r * r) * sizeof(double));
    for (i = 0; i < r * r; i++) V[i] = 0.0;
    for (i = 0; i < r; i++) V[i * r + i] = 1.0;
    for (sweep = 0; sweep < 100; sweep++) {
        double off = 0.0, total = 0.0;
        for (i = 0; i < r; i++)
            for (j = 0; j < r; j++) {
                total += B[i * r + j] * B[i * r + j];
                if (i != j) off += B[i * r + j] * B[i * r + j];
            }
        if (off <= 1e-30 * total) break;
        for (i = 0; i < r - 1; i++)
            for (j = i + 1; j < r; j++) {
                double apq = B[i * r + j], theta, t, cs, sn;
                if (apq == 0.0) continue;
                theta = (B[j * r + j] - B[i * r + i]) / (2.0 * apq);
                t = (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                cs = 1.0 / sqrt(t * t + 1.0);
                sn = t * cs;
                for (k = 0; k < r; k++) {  /* columns i, j */
                    double bi = B[k * r + i], bj = B[k * r + j];
                    B[k * r + i] = cs * bi - sn * bj;
                    B[k * r + j] = sn * bi + cs * bj;
                }
                for (k = 0; k < r; k++) {  /* rows i, j */
                    double bi = B[i * r + k], bj = B[j * r + k];
                    B[i * r + k] = cs * bi - sn * bj;
                    B[j * r + k] = sn * bi + cs * bj;
                }
                for (k = 0; k < r; k++) {
                    double vi = V[k * r + i], vj = V[k * r + j];
                    V[k * r + i] = cs * vi - sn * vj;
                    V[k * r + j] = sn * vi + cs * vj;
                }
            }
    }
    for (i = 0; i < r; i++) lam[i] = B[i * r + i];
}

/* p = -H^-1 g by Cholesky, or where H is not positive definite with its eigenvalues clamped
 * to floor_share of the largest (mirror: their absolute values so clamped). */
void af_newton_direction(const double *H, const double *g, double *p, double *L,
                             double *V, double *lam, double *B, double *t1, long r,
                             double floor_share, int mirror) {
    long i, k;
    if (cholesky(H, L, r)) {
        for (i = 0; i < r; i++) {  /* L y = g */
            double s = g[i];
            for (k = 0; k < i; k++) s -= L[i * r + k] * t1[k];
            t1[i] = s / L[i * r + i];
        }
        for (i = r - 1; i >= 0; i--) {  /* L^T z = y */
            double s = t1[i];
            for (k = i + 1; k < r; k++) s -= L[k * r + i] * p[k];
            p[i] = s / L[i * r + i];
        }
    } else {
        double largest = 0.0;
        jacobi(H, V, lam, B, r);
        for (i = 0; i < r; i++) if (fabs(lam[i]) > largest) largest = fabs(lam[i]);
        for (i = 0; i < r; i++) {
            double s = 0.0, floor_ = floor_share * largest, l = mirror ? fabs(lam[i]) : lam[i];
            for (k = 0; k < r; k++) s += V[k * r + i] * g[k];
            t1[i] = s / (l > floor_ ? l : floor_);
        }
        for (i = 0; i < r; i++) {
            double s = 0.0;
            for (k = 0; k < r; k++) s += V[i * r + k] * t1[k];
            p[i] = s;
        }
    }
    for (i = 0; i < r; i++) p[i] = -p[i];
}
