/* The reduced model's backward-Euler step: positions x = x0 + basis q and the exact elastic
 * energy V(q) = c0 + c1.q + q^T C2 q / 2 + S3[q,q,q] + S4[q,q,q,q], W4 holding S4[a,b,c,:]
 * for the sorted triples a <= b <= c. A step minimizes |q - q_hat|^2 / (2 dt^2) + V(q) - f.q
 * (q_hat = q + dt w, f = basis^T force, the basis mass-orthonormal) by Newton with the
 * Hessian's negative eigenvalues clamped and an Armijo search on the exact quartic along the
 * step, as export/runtime.py's ReducedSimulator does.
 *
 * Controls (named pressures, activations): c1, C2 and S3 are the file's plus each control's
 * part (control_c1, control_C2, control_S3; pressures first, only they have a cubic part)
 * times its coefficient, a pressure's value or an activation a's a (2 - a), formed when the
 * controls are set. A cable's T L(q), L = sum_j |a_j + D_j q| over its segments, adds its
 * gradient and Hessian to the step's, and its change T (L(q + t p) - L(q)) to the search
 * along the step (each segment's (2 d.e + |e|^2) / (|d + e| + |d|), free of cancellation). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "af_internal.h"

#define FLOOR 1.0
#define CONTACT_FLOOR 2.0
#define SMALLEST_STEP 1e-12
#define CLAMP 1e-8

struct af_reduced {
    int n, r;
    long triples;                /* T = r (r + 1) (r + 2) / 6 */
    const double *rest;          /* (n, 3), the model's */
    double *basis, *c1, *C2, *S3, *W4;
    double *constant;            /* (r,) the projected constant force */
    double *work;                /* scratch for a step, cut into the named parts below */
    double *A, *Ap;              /* (T,) W4 at the iterate and along the step */
    double *X, *Y, *H;           /* (r, r): the quartic's and cubic's contractions, Hessian */
    double *L, *V, *J, *cH;      /* (N, N), N = r + 6 obstacles: the whole Hessian's */
    double *g, *p, *x, *t1, *cg, *ts, *load, *terms, *q_hat; /* (N,) */
    double *lam;                 /* (2 N,) */
    int controls, pressures;     /* k controls, the first `pressures` of them pressures */
    int cables;                  /* the last `cables` controls are cables */
    unsigned char *kinds;        /* (k,) 0 a pressure, 1 an activation, 2 a cable */
    int *segments;               /* (cables,) each cable's segment count */
    double *cable_a, *cable_D;   /* (S, 3) and (S, 3, r) */
    double *values;              /* (k,) the controls' values now */
    double *part1, *part2, *part3;  /* (k, r), (k, r, r), (pressures, r, r, r) */
    double *base1, *base2, *base3;  /* the file's c1, C2, S3 (c1, C2, S3: with the controls) */
    af_contact *contact;         /* obstacles, or NULL */
};

void af_reduced_close(af_reduced *m) {
    if (!m) return;
    free(m->basis); free(m->c1); free(m->C2); free(m->S3); free(m->W4); free(m->work);
    free(m->constant); free(m->kinds); free(m->values); free(m->part1); free(m->part2);
    free(m->part3); free(m->base1); free(m->base2); free(m->base3); free(m->segments);
    free(m->cable_a); free(m->cable_D);
    af_contact_close(m->contact);
    free(m);
}

/* A copy of n doubles, or NULL. */
static double *copy_of(const double *a, long n) {
    double *out = (double *)malloc((size_t)n * sizeof(double));
    if (out) memcpy(out, a, (size_t)n * sizeof(double));
    return out;
}

/* The cables' arrays; 0 with a message where they are wrong. */
static int open_cables(af_reduced *m, const af_file *f) {
    long shape[4], rows = 0, c;
    if (!(m->segments = (int *)af_array(f, "cable_segments", 0, "int32", 1, shape))) return 0;
    if (shape[0] != m->cables) goto shape;
    for (c = 0; c < m->cables; c++) {
        if (m->segments[c] < 1) goto shape;
        rows += m->segments[c];
    }
    if (!(m->cable_a = (double *)af_array(f, "cable_a", 0, "float64", 2, shape))) return 0;
    if (shape[0] != rows || shape[1] != 3) goto shape;
    if (!(m->cable_D = (double *)af_array(f, "cable_D", 0, "float64", 3, shape))) return 0;
    if (shape[0] != rows || shape[1] != 3 || shape[2] != m->r) goto shape;
    return 1;
shape:
    af_say(f->error, f->error_size, "%s: the arrays cable_segments (%d,), cable_a (S, 3) and "
           "cable_D (S, 3, r = %d) do not fit: S is the sum of the segment counts, each >= 1",
           f->name, m->cables, m->r);
    return 0;
}

/* The control arrays, where the file has them; 0 with a message where they are wrong. */
static int open_controls(af_reduced *m, const af_file *f) {
    long shape[4], r = m->r, k, i;
    double *defaults;
    int ok;
    if (!af_has_array(f, "control_kinds", 0)) return 1;
    if (!(m->kinds = (unsigned char *)af_array(f, "control_kinds", 0, "uint8", 1, shape)))
        return 0;
    k = m->controls = (int)shape[0];
    for (i = 0; i < k; i++) {
        if (m->kinds[i] > 2 || (i > 0 && m->kinds[i] < m->kinds[i - 1])) {
            af_say(f->error, f->error_size, "%s: array control_kinds: 0 (pressures), 1 "
                   "(activations) then 2 (cables) expected, entry %ld is %d", f->name, i,
                   m->kinds[i]);
            return 0;
        }
        if (!m->kinds[i]) m->pressures++;
        if (m->kinds[i] == 2) m->cables++;
    }
    if (!(m->values = (double *)af_array(f, "control_values", 0, "float64", 1, shape)))
        return 0;
    if (shape[0] != k) goto shape;
    if (!(m->part1 = (double *)af_array(f, "control_c1", 0, "float64", 2, shape))) return 0;
    if (shape[0] != k || shape[1] != r) goto shape;
    if (!(m->part2 = (double *)af_array(f, "control_C2", 0, "float64", 3, shape))) return 0;
    if (shape[0] != k || shape[1] != r || shape[2] != r) goto shape;
    if (!(m->part3 = (double *)af_array(f, "control_S3", 0, "float64", 4, shape))) return 0;
    if (shape[0] != m->pressures || shape[1] != r || shape[2] != r || shape[3] != r) goto shape;
    if (m->cables && !open_cables(m, f)) return 0;
    m->base1 = copy_of(m->c1, r);
    m->base2 = copy_of(m->C2, r * r);
    m->base3 = copy_of(m->S3, r * r * r);
    defaults = copy_of(m->values, k);
    if (!m->base1 || !m->base2 || !m->base3 || !defaults) {
        free(defaults);
        af_say(f->error, f->error_size, "no memory for a model's controls");
        return 0;
    }
    ok = af_reduced_set_controls(m, defaults, NULL, f->error, f->error_size) == AF_OK;
    free(defaults);
    return ok;
shape:
    af_say(f->error, f->error_size, "%s: the arrays control_values (k,), control_c1 (k, r), "
           "control_C2 (k, r, r) and control_S3 (pressures, r, r, r) do not fit %ld controls "
           "(%d pressures) and r = %ld", f->name, k, m->pressures, r);
    return 0;
}

int af_reduced_controls(const af_reduced *m) { return m->controls; }

double af_reduced_control(const af_reduced *m, int i) { return m->values[i]; }

int af_reduced_check_controls(const af_reduced *m, const double *values, const char *names,
                              char *error, size_t error_size) {
    long i, c;
    const char *name = names;
    for (c = 0; c < m->controls; c++) {
        double v = values[c];
        if (!isfinite(v) || (m->kinds[c] == 1 && !(v >= 0.0 && v < 1.0)) ||
            (m->kinds[c] == 2 && !(v >= 0.0))) {
            for (i = 0; names && i < c; i++) name += strlen(name) + 1;
            af_say(error, error_size, "controls: %s%s%scontrol %ld is %s; got %g",
                   names ? "'" : "", names ? name : "", names ? "', " : "", c,
                   m->kinds[c] == 1 ? "an activation, in [0, 1)" : m->kinds[c] == 2 ?
                   "a cable, a tension >= 0 N" : "a pressure, a finite number of Pa", v);
            return AF_BAD_INPUT;
        }
    }
    return AF_OK;
}

int af_reduced_set_controls(af_reduced *m, const double *values, const char *names,
                            char *error, size_t error_size) {
    long r = m->r, i, j, c;
    if (af_reduced_check_controls(m, values, names, error, error_size)) return AF_BAD_INPUT;
    memcpy(m->c1, m->base1, (size_t)r * sizeof(double));
    memcpy(m->C2, m->base2, (size_t)(r * r) * sizeof(double));
    if (m->pressures) memcpy(m->S3, m->base3, (size_t)(r * r * r) * sizeof(double));
    for (c = 0; c < m->controls; c++) {
        double v = m->values[c] = values[c];
        double beta = m->kinds[c] == 1 ? v * (2.0 - v) : m->kinds[c] == 2 ? 0.0 : v;
        const double *p1 = m->part1 + c * r, *p2 = m->part2 + c * r * r;
        if (beta == 0.0) continue;
        for (i = 0; i < r; i++) m->c1[i] += beta * p1[i];
        for (i = 0; i < r * r; i++) m->C2[i] += beta * p2[i];
        if (c < m->pressures) {
            const double *p3 = m->part3 + c * r * r * r;
            for (j = 0; j < r * r * r; j++) m->S3[j] += beta * p3[j];
        }
    }
    return AF_OK;
}

/* m->work allocated and cut into its parts (N = r + 6 per obstacle: a step's unknowns at
 * most); 0 where out of memory. */
static int cut_work(af_reduced *m) {
    long r = m->r, N = r + 6L * af_contact_count(m->contact), T = m->triples;
    double *w = m->work = (double *)malloc((size_t)(2 * T + 3 * r * r + 4 * N * N + 12 * N + 1)
                                           * sizeof(double));
    if (!w) return 0;
    m->A = w; m->Ap = w += T; m->X = w += T; m->Y = w += r * r; m->H = w += r * r;
    m->L = w += r * r; m->V = w += N * N; m->J = w += N * N; m->cH = w += N * N;
    m->g = w += N * N; m->p = w += N; m->x = w += N; m->t1 = w += N; m->cg = w += N;
    m->ts = w += N; m->load = w += N; m->terms = w += N; m->q_hat = w += N; m->lam = w + N;
    return 1;
}

af_reduced *af_reduced_open(const af_file *f, int n, const double *rest) {
    long shape[4], r;
    af_reduced *m = (af_reduced *)calloc(1, sizeof *m);
    if (!m) {
        af_say(f->error, f->error_size, "no memory for a model");
        return NULL;
    }
    m->n = n;
    m->rest = rest;
    if (!(m->basis = (double *)af_array(f, "basis", 1, "float64", 3, shape))) goto fail;
    r = m->r = (int)shape[2];
    if (shape[0] != n || shape[1] != 3) {
        af_say(f->error, f->error_size, "%s: array basis%s has shape (%ld, %ld, %ld), expected "
               "(%d, 3, r): one row per vertex", f->name, f->tag, shape[0], shape[1], r, n);
        goto fail;
    }
    m->triples = r * (r + 1) * (r + 2) / 6;
    if (!(m->c1 = (double *)af_array(f, "c1", 1, "float64", 1, shape))) goto fail;
    if (shape[0] != r) goto shape;
    if (!(m->C2 = (double *)af_array(f, "C2", 1, "float64", 2, shape))) goto fail;
    if (shape[0] != r || shape[1] != r) goto shape;
    if (!(m->S3 = (double *)af_array(f, "S3", 1, "float64", 3, shape))) goto fail;
    if (shape[0] != r || shape[1] != r || shape[2] != r) goto shape;
    if (!(m->W4 = (double *)af_array(f, "W4", 1, "float64", 2, shape))) goto fail;
    if (shape[0] != m->triples || shape[1] != r) goto shape;
    m->constant = (double *)calloc((size_t)r + 1, sizeof(double));
    if (!m->constant) goto memory;
    if (!open_controls(m, f)) goto fail;
    {
        int failed;
        m->contact = af_contact_open(f, (int)r, &failed);
        if (failed) goto fail;
    }
    if (!cut_work(m)) goto memory;
    return m;
memory:
    af_say(f->error, f->error_size, "no memory for a model of r = %ld", r);
    goto fail;
shape:
    af_say(f->error, f->error_size, "%s: the arrays c1, C2, S3 and W4%s do not fit a basis of "
           "r = %ld coordinates ((r,), (r, r), (r, r, r), (r (r + 1) (r + 2) / 6, r))", f->name,
           f->tag, r);
fail:
    af_reduced_close(m);
    return NULL;
}

int af_reduced_size(const af_reduced *m) { return m->r; }

af_contact *af_reduced_contact(const af_reduced *m) { return m->contact; }

void af_reduced_basis_rows(const af_reduced *m, const int *nodes, const double *weights,
                           int count, double *e0, double *E) {
    long r = m->r, i, j, k;
    for (i = 0; i < 3; i++) e0[i] = 0.0;
    for (i = 0; i < 3 * r; i++) E[i] = 0.0;
    for (j = 0; j < count; j++)
        for (i = 0; i < 3; i++) {
            const double *row = m->basis + (3L * nodes[j] + i) * r;
            e0[i] += weights[j] * m->rest[3L * nodes[j] + i];
            for (k = 0; k < r; k++) E[i * r + k] += weights[j] * row[k];
        }
}

void af_reduced_place(const af_reduced *m, const double *q, double *x) {
    long i, k, r = m->r;
    for (i = 0; i < 3L * m->n; i++) {
        double s = 0.0;
        const double *row = m->basis + i * r;
        for (k = 0; k < r; k++) s += row[k] * q[k];
        x[i] = m->rest[i] + s;
    }
}

/* out (T,) = W4 v */
static void w4_times(const af_reduced *m, const double *v, double *out) {
    long t, r = m->r;
    for (t = 0; t < m->triples; t++) out[t] = af_dot(m->W4 + t * r, v, r);
}

/* The cubic forms T[p, p, p] of A and of Ap (sorted triples as in contract): each sorted
 * triple weighted by its number of orderings. */
static void cubic_forms(const double *A, const double *Ap, const double *p, long r,
                        double *mixed, double *pure) {
    long a, b, c, t = 0;
    double m = 0.0, q = 0.0;
    for (a = 0; a < r; a++)
        for (b = a; b < r; b++) {
            double pab = p[a] * p[b], w = pab * p[b] * (a == b ? 1.0 : 3.0);  /* c = b */
            m += w * A[t];
            q += w * Ap[t];
            t++;
            w = (a == b ? 3.0 : 6.0) * pab;                                   /* c > b */
            for (c = b + 1; c < r; c++) {
                m += w * p[c] * A[t];
                q += w * p[c] * Ap[t];
                t++;
            }
        }
    *mixed = m;
    *pure = q;
}

/* Y[a, b] = S3[a, b, :] . u */
static void s3_times(const af_reduced *m, const double *u, double *Y) {
    long ab, r = m->r;
    for (ab = 0; ab < r * r; ab++) Y[ab] = af_dot(m->S3 + ab * r, u, r);
}

/* u^T M u for an r x r matrix M */
static double form(const double *M, const double *u, long r) {
    double s = 0.0;
    long a;
    for (a = 0; a < r; a++) s += u[a] * af_dot(M + a * r, u, r);
    return s;
}

/* load (r,) += basis^T force (n x 3) */
static void project(const af_reduced *m, const double *force, double *load) {
    long i, k, r = m->r;
    for (i = 0; i < 3L * m->n; i++) {
        const double *row = m->basis + i * r;
        double f = force[i];
        if (f != 0.0) for (k = 0; k < r; k++) load[k] += f * row[k];
    }
}

int af_reduced_set_force(af_reduced *m, const double *force) {
    long k;
    for (k = 0; k < m->r; k++) m->constant[k] = 0.0;
    if (force) project(m, force, m->constant);
    return AF_OK;
}

/* The pulled cables' gradient into g and Hessian into H (r, r), both zeroed first; returns
 * whether any cable is pulled. */
static int cable_terms(const af_reduced *m, const double *q, double *g, double *H) {
    long r = m->r, c, j, i, a, b, k, row = 0;
    int any = 0;
    for (i = 0; i < r; i++) g[i] = 0.0;
    for (i = 0; i < r * r; i++) H[i] = 0.0;
    for (c = 0; c < m->cables; c++) {
        double T = m->values[m->controls - m->cables + c];
        for (j = 0; j < m->segments[c]; j++, row++) {
            const double *D = m->cable_D + row * 3 * r;
            double d[3], t[3], l = 0.0, P[9];
            if (!(T > 0.0)) continue;
            any = 1;
            for (a = 0; a < 3; a++) {
                d[a] = m->cable_a[row * 3 + a] + af_dot(D + a * r, q, r);
                l += d[a] * d[a];
            }
            l = sqrt(l);
            if (!(l > 0.0)) continue;
            for (a = 0; a < 3; a++) t[a] = d[a] / l;
            for (a = 0; a < 3; a++)
                for (b = 0; b < 3; b++) P[a * 3 + b] = T * ((a == b) - t[a] * t[b]) / l;
            for (i = 0; i < r; i++) {
                double s = 0.0;
                for (a = 0; a < 3; a++) s += t[a] * D[a * r + i];
                g[i] += T * s;
            }
            for (i = 0; i < r; i++) {
                double PD[3];
                for (a = 0; a < 3; a++)
                    PD[a] = P[a * 3] * D[i] + P[a * 3 + 1] * D[r + i] + P[a * 3 + 2] * D[2 * r + i];
                for (k = 0; k < r; k++)
                    H[i * r + k] += PD[0] * D[k] + PD[1] * D[r + k] + PD[2] * D[2 * r + k];
            }
        }
    }
    return any;
}

/* dL/dq (r,) into g of cable `cable` (index among the cables) at q. */
static void cable_slope(const af_reduced *m, int cable, const double *q, double *g) {
    long r = m->r, c, j, i, a, row = 0;
    for (c = 0; c < cable; c++) row += m->segments[c];
    for (i = 0; i < r; i++) g[i] = 0.0;
    for (j = 0; j < m->segments[cable]; j++, row++) {
        const double *D = m->cable_D + row * 3 * r;
        double d[3], l = 0.0;
        for (a = 0; a < 3; a++) {
            d[a] = m->cable_a[row * 3 + a] + af_dot(D + a * r, q, r);
            l += d[a] * d[a];
        }
        l = sqrt(l);
        if (!(l > 0.0)) continue;
        for (i = 0; i < r; i++)
            g[i] += (d[0] * D[i] + d[1] * D[r + i] + d[2] * D[2 * r + i]) / l;
    }
}

/* The pulled cables' sum of T (L(q + step) - L(q)). */
static double cable_change(const af_reduced *m, const double *q, const double *step) {
    long r = m->r, c, j, a, row = 0;
    double total = 0.0;
    for (c = 0; c < m->cables; c++) {
        double T = m->values[m->controls - m->cables + c];
        for (j = 0; j < m->segments[c]; j++, row++) {
            const double *D = m->cable_D + row * 3 * r;
            double d[3], e[3], ld = 0.0, le = 0.0, num = 0.0;
            if (!(T > 0.0)) continue;
            for (a = 0; a < 3; a++) {
                d[a] = m->cable_a[row * 3 + a] + af_dot(D + a * r, q, r);
                e[a] = af_dot(D + a * r, step, r);
                num += (2.0 * d[a] + e[a]) * e[a];
                ld += d[a] * d[a];
                le += (d[a] + e[a]) * (d[a] + e[a]);
            }
            ld = sqrt(ld) + sqrt(le);
            total += T * num / (ld > 0.0 ? ld : 1.0);
        }
    }
    return total;
}

/* Minimize |x - q_hat|^2 inertia / 2 + V(x) - load.x from x in place to a reduced
 * gradient of tolerance + rtol |dV/dq(x0)| or the round-off floor: the iterations taken, or
 * AF_NOT_CONVERGED with a message. q_hat is read only where inertia > 0. x holds q (r) and,
 * in a step with free obstacles, their moves (the contact's unknowns) after it: n in all. */
static int minimize(af_reduced *m, double *x, const double *q_hat, double inertia,
                    const double *load, double tolerance, double rtol, int max_iter,
                    char *error, size_t error_size) {
    long r = m->r, n = r + af_contact_unknowns(m->contact), nn = n * n, i, k, it;
    double *A = m->A, *Ap = m->Ap, *X = m->X, *Y = m->Y, *H = m->H, *g = m->g, *p = m->p,
           *terms = m->terms, *cH = m->cH, *cg = m->cg, *ts = m->ts;
    double residual = 0.0, eps = 2.220446049250313e-16;
    w4_times(m, x, A);
    for (it = 0; it <= max_iter; it++) {
        double a1, a2, a3, pure, mixed, step = 1.0, floor_, pull = 0.0, touch = 0.0,
               reach = 0.0;
        /* the cables' gradient and Hessian (r, r) into scratch the direction reuses */
        int pulled = m->cables && cable_terms(m, x, m->lam, m->L), extra = pulled || m->contact;
        if (m->contact) {
            const double *tg, *tH;
            touch = af_contact_terms(m->contact, x, &tg, &tH, &reach);
            memcpy(cH, tH, (size_t)nn * sizeof(double));
            memcpy(cg, tg, (size_t)n * sizeof(double));
            reach *= CONTACT_FLOOR * eps;
        } else if (pulled) {
            memset(cH, 0, (size_t)nn * sizeof(double));
            memset(cg, 0, (size_t)n * sizeof(double));
        }
        for (i = 0; pulled && i < r; i++) {
            cg[i] += m->lam[i];
            for (k = 0; k < r; k++) cH[i * n + k] += m->L[i * r + k];
        }
        af_contract(A, x, X, r);
        s3_times(m, x, Y);
        for (i = 0; i < r; i++) {
            double s = m->c1[i];
            for (k = 0; k < r; k++)
                s += (m->C2[i * r + k] + 3.0 * Y[i * r + k] + 4.0 * X[i * r + k]) * x[k];
            g[i] = extra ? s + cg[i] : s;
        }
        for (i = r; i < n; i++) g[i] = cg[i];
        if (it == 0) tolerance += rtol * sqrt(af_dot(g, g, r));
        for (i = 0; i < r; i++) {
            g[i] += (inertia > 0.0 ? inertia * (x[i] - q_hat[i]) : 0.0) - load[i];
            for (k = 0; k < r; k++)
                H[i * r + k] = m->C2[i * r + k] + 6.0 * Y[i * r + k] + 12.0 * X[i * r + k]
                               + (i == k ? inertia : 0.0);
        }
        if (extra)       /* cH: the whole Hessian; H keeps the quartic's part for the search */
            for (i = 0; i < r; i++)
                for (k = 0; k < r; k++) cH[i * n + k] += H[i * r + k];
        residual = sqrt(af_dot(g, g, n));
        if (!isfinite(residual)) {
            af_say(error, error_size, "step: the reduced force is not finite at iteration %ld",
                   it);
            return AF_NOT_CONVERGED;
        }
        for (i = 0; i < n; i++) {
            const double *row = extra ? cH + i * n : H + i * r;
            double s = 0.0;
            for (k = 0; k < n; k++) s += fabs(row[k]) * fabs(x[k]);
            terms[i] = s + (i < r ? fabs(load[i]) + fabs(m->c1[i]) : 0.0);
        }
        floor_ = FLOOR * eps * (double)n * sqrt(af_dot(terms, terms, n));
        if (reach > floor_) floor_ = reach;
        if (residual <= (tolerance > floor_ ? tolerance : floor_)) return (int)it;
        if (it == max_iter) break;
        af_newton_direction(extra ? cH : H, g, p, m->L, m->V, m->lam, m->J, m->t1, n, CLAMP, 0);
        a1 = af_dot(g, p, n);
        if (!(a1 < 0.0)) break;
        a2 = 0.5 * form(H, p, r);
        if (extra) pull = af_dot(cg, p, n);
        w4_times(m, p, Ap);
        cubic_forms(A, Ap, p, r, &mixed, &pure);
        s3_times(m, p, Y);
        a3 = form(Y, p, r) + 4.0 * mixed;
        if (m->contact) {
            double share = af_contact_limit(m->contact, x, p);
            if (share < step) step = share;
        }
        while (step >= SMALLEST_STEP) {
            double beside = 0.0;    /* the cables' and the contact's change, less its slope */
            if (extra) {
                for (k = 0; k < n; k++) ts[k] = step * p[k];
                if (pulled) beside += cable_change(m, x, ts);
                if (m->contact) beside += af_contact_change(m->contact, x, ts, touch);
                beside = beside / step - pull;
            }
            if (!(step * (a2 + step * (a3 + step * pure)) + beside > -(1.0 - AF_ARMIJO) * a1))
                break;
            step *= 0.5;
        }
        if (step < SMALLEST_STEP) break;
        for (k = 0; k < n; k++) x[k] += step * p[k];
        if (m->contact) af_contact_settle(m->contact, x);
        for (k = 0; k < m->triples; k++) A[k] += step * Ap[k];
    }
    af_say(error, error_size, "step: Newton stopped at |g| = %.3g, its tolerance %.3g, after "
           "%ld iterations", residual, tolerance, it);
    return AF_NOT_CONVERGED;
}

int af_reduced_advance(af_reduced *m, double *q, double *w, const double *force, double dt,
                       double rtol, int max_iter, char *error, size_t error_size) {
    long r = m->r, n, k;
    double *x = m->x, *load = m->load, *q_hat = m->q_hat;
    int result;
    for (k = 0; k < r; k++) load[k] = m->constant[k];
    if (force) project(m, force, load);
    for (k = 0; k < r; k++) x[k] = q_hat[k] = q[k] + dt * w[k];
    if (m->contact) {      /* friction lagged at q; the start clear of the obstacles */
        double share, *z = m->ts;
        int halved;
        af_contact_start(m->contact, q, dt);
        n = r + af_contact_unknowns(m->contact);
        for (k = 0; k < r; k++) {
            z[k] = q[k];
            x[k] = q_hat[k] - q[k];
        }
        for (k = r; k < n; k++) z[k] = 0.0;
        af_contact_guess(m->contact, x + r);
        share = af_contact_limit(m->contact, z, x);
        for (k = 0; k < n; k++) x[k] *= share;
        /* a turn's collision test is along a chord: the start checked, halved */
        for (halved = 0; halved < 60 && af_contact_turning(m->contact); halved++) {
            for (k = 0; k < n; k++) m->p[k] = z[k] + x[k];
            if (isfinite(af_contact_energy(m->contact, m->p))) break;
            for (k = 0; k < n; k++) x[k] *= 0.5;
        }
        for (k = 0; k < n; k++) x[k] = halved == 60 ? z[k] : z[k] + x[k];
        af_contact_settle(m->contact, x);
    }
    result = minimize(m, x, q_hat, 1.0 / (dt * dt),
                      load, rtol * (sqrt(af_dot(load, load, r)) + sqrt(af_dot(w, w, r)) / dt),
                      rtol, max_iter, error, error_size);
    if (result < 0) return result;
    if (m->contact) af_contact_finish(m->contact, x, dt);
    for (k = 0; k < r; k++) {
        w[k] = (x[k] - q[k]) / dt;
        q[k] = x[k];
    }
    return result;
}

int af_reduced_static(af_reduced *m, double *q, double rtol, int max_iter, char *error,
                      size_t error_size) {
    long r = m->r;
    int result;
    if (m->contact) af_contact_start(m->contact, q, 0.0);
    result = minimize(m, q, NULL, 0.0, m->constant,
                      rtol * sqrt(af_dot(m->constant, m->constant, r)), rtol, max_iter, error,
                      error_size);
    if (result >= 0 && m->contact) af_contact_finish(m->contact, q, 0.0);
    return result;
}

void af_reduced_control_slopes(af_reduced *m, const double *q, double *slopes) {
    long r = m->r, rr = r * r, i, k, c;
    double *A = m->A, *X = m->X, *Y = m->Y, *H = m->H, *g = m->g, *p = m->p, *cH = m->cH,
           *cg = m->cg;
    int pulled = m->cables && cable_terms(m, q, cg, cH);
    w4_times(m, q, A);
    af_contract(A, q, X, r);
    s3_times(m, q, Y);
    for (i = 0; i < rr; i++) H[i] = m->C2[i] + 6.0 * Y[i] + 12.0 * X[i] + (pulled ? cH[i] : 0.0);
    for (c = 0; c < m->controls; c++) {
        const double *p1 = m->part1 + c * r, *p2 = m->part2 + c * rr;
        double v = m->values[c], slope = m->kinds[c] == 1 ? 2.0 - 2.0 * v : 1.0;
        if (m->kinds[c] == 2) {
            cable_slope(m, (int)(c - (m->controls - m->cables)), q, g);
        } else for (i = 0; i < r; i++) {
            double s = p1[i];
            for (k = 0; k < r; k++) s += p2[i * r + k] * q[k];
            if (c < m->pressures) {
                const double *p3 = m->part3 + c * rr * r + i * rr;
                for (k = 0; k < rr; k++) s += 3.0 * p3[k] * q[k / r] * q[k % r];
            }
            g[i] = slope * s;
        }
        af_newton_direction(H, g, p, m->L, m->V, m->lam, m->J, m->t1, r, CLAMP, 0);
        for (i = 0; i < r; i++) slopes[i * m->controls + c] = p[i];
    }
}
