/* Inverse statics in a reduced model: the controls within bounds that bring an effector (a
 * weighted sum of nodes, e = e0 + E q) to a target at static equilibrium, as
 * anisofem.reduced.reach does: Levenberg-Marquardt on |e(q(u)) - target|^2 in the controls
 * scaled to [0, 1] by their bounds, each step a small bounded least-squares problem solved by
 * a primal active set, dq/du = -H^-1 dg/du at each equilibrium; from the controls now, then
 * where that ends short of the target from the bounds' middle, the nearer kept. */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "af_internal.h"

#define DAMPING 1e-3
#define SOFTER 3.0
#define STIFFER 4.0
#define LARGEST 1e8
#define STATIONARY 1e-9
#define CRAWL 1e-6
#define SOLVE_RTOL 1e-8
#define SOLVE_ITERATIONS 50

/* Scratch of a reach over k controls and r coordinates. */
typedef struct {
    long k, r;
    double *E, e0[3], target[3], tolerance, *low, *high, *width;
    double *u, *s, *trial, *q, *q_trial, *slopes, *J, *A, *b, *d, *goal, *step, *chol, *rhs;
    signed char *bound;
    int *free_;
    af_reduced *m;
} reach_t;

typedef struct {
    double distance;
    int iterations, reached;
} outcome;

/* x (k,) solves the k x k positive definite system M x = y (row-major; chol: scratch). */
static void solve_spd(const double *M, const double *y, double *x, double *chol, long k) {
    long i, j, l;
    for (i = 0; i < k; i++)
        for (j = 0; j <= i; j++) {
            double s = M[i * k + j];
            for (l = 0; l < j; l++) s -= chol[i * k + l] * chol[j * k + l];
            chol[i * k + j] = i == j ? sqrt(s > 0.0 ? s : DBL_MIN) : s / chol[j * k + j];
        }
    for (i = 0; i < k; i++) {
        double s = y[i];
        for (l = 0; l < i; l++) s -= chol[i * k + l] * x[l];
        x[i] = s / chol[i * k + i];
    }
    for (i = k - 1; i >= 0; i--) {
        double s = x[i];
        for (l = i + 1; l < k; l++) s -= chol[l * k + i] * x[l];
        x[i] = s / chol[i * k + i];
    }
}

/* d (k,) minimizing |res + J d|^2 + damping |d|^2 with low <= d <= high (low <= 0 <= high),
 * J (3 x k): the primal active set of anisofem.reduced.reach.bounded_least_squares. */
static void bounded_least_squares(reach_t *w, const double *res, const double *low,
                                  const double *high, double damping) {
    long k = w->k, i, j, a, pass;
    double *A = w->A, *b = w->b, *d = w->d;
    for (i = 0; i < k; i++) {
        for (j = 0; j < k; j++) {
            double s = 0.0;
            for (a = 0; a < 3; a++) s += w->J[a * k + i] * w->J[a * k + j];
            A[i * k + j] = s + (i == j ? damping : 0.0);
        }
        b[i] = 0.0;
        for (a = 0; a < 3; a++) b[i] += w->J[a * k + i] * res[a];
        d[i] = 0.0;
        w->bound[i] = 0;
    }
    for (pass = 0; pass < 4 * k + 4; pass++) {
        long n = 0, hit = -1, best = -1;
        double t = 1.0, most = 0.0;
        for (i = 0; i < k; i++)
            if (!w->bound[i]) w->free_[n++] = (int)i;
        memcpy(w->goal, d, (size_t)k * sizeof(double));
        if (n) {
            double *M = w->chol + k * k, *x = w->rhs + k;
            for (i = 0; i < n; i++) {
                double s = -b[w->free_[i]];
                for (j = 0; j < k; j++)
                    if (w->bound[j]) s -= A[w->free_[i] * k + j] * d[j];
                w->rhs[i] = s;
                for (j = 0; j < n; j++) M[i * n + j] = A[w->free_[i] * k + w->free_[j]];
            }
            solve_spd(M, w->rhs, x, w->chol, n);
            for (i = 0; i < n; i++) w->goal[w->free_[i]] = x[i];
        }
        for (i = 0; i < k; i++) w->step[i] = w->goal[i] - d[i];
        for (i = 0; i < n; i++) {
            long f = w->free_[i];
            double ratio;
            if (w->step[f] < 0 && d[f] + w->step[f] < low[f])
                ratio = (low[f] - d[f]) / w->step[f];
            else if (w->step[f] > 0 && d[f] + w->step[f] > high[f])
                ratio = (high[f] - d[f]) / w->step[f];
            else
                continue;
            if (ratio < t) {
                t = ratio;
                hit = f;
            }
        }
        for (i = 0; i < k; i++) d[i] += t * w->step[i];
        if (hit >= 0) {
            w->bound[hit] = w->step[hit] < 0 ? -1 : 1;
            d[hit] = w->bound[hit] < 0 ? low[hit] : high[hit];
            continue;
        }
        for (i = 0; i < k; i++) {
            double g = b[i], pull;
            for (j = 0; j < k; j++) g += A[i * k + j] * d[j];
            pull = w->bound[i] < 0 ? -g : w->bound[i] > 0 ? g : 0.0;
            if (pull > most) {
                most = pull;
                best = i;
            }
        }
        if (best < 0) return;
        w->bound[best] = 0;
    }
}

/* The equilibrium under controls u into q, Newton from q (from 0 where start is 0, or where
 * that fails). */
static void equilibrium(reach_t *w, const double *u, double *q, int start) {
    long i;
    af_reduced_set_controls(w->m, u, NULL, NULL, 0);
    if (!start) memset(q, 0, (size_t)w->r * sizeof(double));
    if (af_reduced_static(w->m, q, SOLVE_RTOL, SOLVE_ITERATIONS, NULL, 0) < 0 && start) {
        for (i = 0; i < w->r; i++) q[i] = 0.0;
        af_reduced_static(w->m, q, SOLVE_RTOL, SOLVE_ITERATIONS, NULL, 0);
    }
}

/* res (3,) = e0 + E q - target; returns |res|^2. */
static double residual(const reach_t *w, const double *q, double *res) {
    long a;
    double s = 0.0;
    for (a = 0; a < 3; a++) {
        res[a] = w->e0[a] + af_dot(w->E + a * w->r, q, w->r) - w->target[a];
        s += res[a] * res[a];
    }
    return s;
}

/* Whether the squared distance has no descent within the bounds at scaled controls s. */
static int stationary(const reach_t *w, const double *res) {
    long i, a, k = w->k;
    double gg = 0.0, jj = 0.0, rr = 0.0;
    for (i = 0; i < k; i++) {
        double g = 0.0;
        for (a = 0; a < 3; a++) {
            g += w->J[a * k + i] * res[a];
            jj += w->J[a * k + i] * w->J[a * k + i];
        }
        if ((w->s[i] <= 0.0 && g > 0) || (w->s[i] >= 1.0 && g < 0)) g = 0.0;
        gg += g * g;
    }
    for (a = 0; a < 3; a++) rr += res[a] * res[a];
    return sqrt(gg) <= STATIONARY * sqrt(jj) * sqrt(rr);
}

/* One descent from the controls in w->u (within the bounds), their equilibrium's Newton from
 * w->q where warm (else 0); its result in w->u, w->q. */
static outcome descend(reach_t *w, int max_iter, int warm) {
    long k = w->k, r = w->r, i, a, c;
    double res[3], moved[3], distance = 0.0, damping = -1.0, lo[64], hi[64];
    int it;
    outcome out;
    equilibrium(w, w->u, w->q, warm);
    residual(w, w->q, res);
    for (it = 0; it <= max_iter; it++) {
        double scale = DBL_MIN, now;
        int accepted = 0;
        distance = sqrt(res[0] * res[0] + res[1] * res[1] + res[2] * res[2]);
        if (distance <= w->tolerance || it == max_iter) break;
        af_reduced_control_slopes(w->m, w->q, w->slopes);
        for (a = 0; a < 3; a++)
            for (c = 0; c < k; c++) {
                double s = 0.0;
                for (i = 0; i < r; i++) s += w->E[a * r + i] * w->slopes[i * k + c];
                w->J[a * k + c] = s * w->width[c];
            }
        for (c = 0; c < k; c++) {
            double col = 0.0;
            w->s[c] = (w->u[c] - w->low[c]) / w->width[c];
            for (a = 0; a < 3; a++) col += w->J[a * k + c] * w->J[a * k + c];
            if (col > scale) scale = col;
        }
        if (stationary(w, res)) break;
        if (damping < 0.0) damping = DAMPING * scale;
        now = res[0] * res[0] + res[1] * res[1] + res[2] * res[2];
        for (c = 0; c < k; c++) {
            lo[c] = -w->s[c];
            hi[c] = 1.0 - w->s[c];
        }
        while (damping <= LARGEST * scale) {
            bounded_least_squares(w, res, lo, hi, damping);
            for (c = 0; c < k; c++) {
                double v = w->low[c] + (w->s[c] + w->d[c]) * w->width[c];
                w->trial[c] = v < w->low[c] ? w->low[c] : v > w->high[c] ? w->high[c] : v;
            }
            for (i = 0; i < r; i++) {      /* from its tangent: q + dq/du (trial - u) */
                double s = w->q[i];
                for (c = 0; c < k; c++) s += w->slopes[i * k + c] * (w->trial[c] - w->u[c]);
                w->q_trial[i] = s;
            }
            equilibrium(w, w->trial, w->q_trial, 1);
            if (residual(w, w->q_trial, moved) < now) {
                damping /= SOFTER;
                accepted = 1;
                break;
            }
            damping *= STIFFER;
        }
        if (!accepted) break;
        memcpy(w->u, w->trial, (size_t)k * sizeof(double));
        memcpy(w->q, w->q_trial, (size_t)r * sizeof(double));
        memcpy(res, moved, sizeof res);
        if (now - (res[0] * res[0] + res[1] * res[1] + res[2] * res[2]) <= CRAWL * now) {
            distance = sqrt(res[0] * res[0] + res[1] * res[1] + res[2] * res[2]);
            break;
        }
    }
    out.distance = distance;
    out.iterations = it;
    out.reached = distance <= w->tolerance;
    return out;
}

int af_reduced_reach(af_reduced *m, const int *nodes, const double *weights, int count,
                     const double *target, const double *low, const double *high,
                     double tolerance, int max_iter, double *q0,
                     int warm, double *controls, double *position, int *iterations,
                     char *error, size_t error_size) {
    long k = af_reduced_controls(m), r = af_reduced_size(m), c;
    reach_t w;
    outcome first, second;
    double *now = (double *)malloc((size_t)k * sizeof(double)), *keep_u, *keep_q;
    /* E 3r; low, high, width, u, s, trial, b, d 8k; q, q_trial 2r; slopes rk; J 3k; goal,
       step 2k; A k^2; chol 2k^2; rhs 2k; keep_u k; keep_q r */
    double *block = (double *)calloc((size_t)(6 * r + r * k + 16 * k + 3 * k * k + 1),
                                     sizeof(double));
    signed char *bound = (signed char *)malloc((size_t)k + 1);
    int *free_ = (int *)malloc(((size_t)k + 1) * sizeof(int)), result;
    if (!now || !block || !bound || !free_ || k > 64) {
        free(now); free(block); free(bound); free(free_);
        af_say(error, error_size, k > 64 ? "reach: at most 64 controls" : "no memory to reach");
        return k > 64 ? AF_BAD_INPUT : AF_NO_MEMORY;
    }
    for (c = 0; c < k; c++) now[c] = af_reduced_control(m, c);
    w.k = k;
    w.r = r;
    w.m = m;
    w.E = block;
    w.low = w.E + 3 * r;
    w.high = w.low + k;
    w.width = w.high + k;
    w.u = w.width + k;
    w.s = w.u + k;
    w.trial = w.s + k;
    w.b = w.trial + k;
    w.d = w.b + k;
    w.q = w.d + k;
    w.q_trial = w.q + r;
    w.slopes = w.q_trial + r;
    w.J = w.slopes + r * k;
    w.goal = w.J + 3 * k;
    w.step = w.goal + k;
    w.A = w.step + k;
    w.chol = w.A + k * k;          /* chol, then the free block M: 2 k^2 */
    w.rhs = w.chol + 2 * k * k;    /* rhs, then x: 2 k */
    keep_u = w.rhs + 2 * k;
    keep_q = keep_u + k;
    w.bound = bound;
    w.free_ = free_;
    af_reduced_basis_rows(m, nodes, weights, count, w.e0, w.E);
    memcpy(w.target, target, sizeof w.target);
    w.tolerance = tolerance;
    for (c = 0; c < k; c++) {
        double v = now[c];
        w.low[c] = low[c];
        w.high[c] = high[c];
        w.width[c] = high[c] - low[c];
        w.u[c] = v < low[c] ? low[c] : v > high[c] ? high[c] : v;
    }
    if (warm) memcpy(w.q, q0, (size_t)r * sizeof(double));
    first = descend(&w, max_iter, warm);
    if (!first.reached) {
        memcpy(keep_u, w.u, (size_t)k * sizeof(double));
        memcpy(keep_q, w.q, (size_t)r * sizeof(double));
        for (c = 0; c < k; c++) w.u[c] = 0.5 * (low[c] + high[c]);
        second = descend(&w, max_iter, 0);
        second.iterations += first.iterations;
        if (!(second.distance < first.distance)) {
            memcpy(w.u, keep_u, (size_t)k * sizeof(double));
            memcpy(w.q, keep_q, (size_t)r * sizeof(double));
            second.distance = first.distance;
            second.reached = first.reached;
        }
        first = second;
    }
    memcpy(controls, w.u, (size_t)k * sizeof(double));
    memcpy(q0, w.q, (size_t)r * sizeof(double));
    for (c = 0; c < 3; c++) position[c] = w.e0[c] + af_dot(w.E + c * r, w.q, r);
    *iterations = first.iterations;
    af_reduced_set_controls(m, now, NULL, NULL, 0);
    if (first.reached) {
        result = AF_OK;
    } else {
        af_say(error, error_size, "out of reach: the nearest point found is %.3g m from the "
               "target (the controls' bounds, or the body, stop it)", first.distance);
        result = AF_OUT_OF_REACH;
    }
    free(now); free(block); free(bound); free(free_);
    return result;
}
