/* The reduced model's backward-Euler step in C99 (see anisofem_reduced.h): positions x = x0 +
 * basis q and the exact elastic energy V(q) = c0 + c1.q + q^T C2 q / 2 + S3[q,q,q] +
 * S4[q,q,q,q], W4 holding S4[a,b,c,:] for the sorted triples a <= b <= c. A step minimizes
 * |q - q_hat|^2 / (2 dt^2) + V(q) - f.q (q_hat = q + dt w, f = basis^T force, the basis
 * mass-orthonormal) by Newton with the Hessian's negative eigenvalues clamped and an Armijo
 * search on the exact quartic along the step, as export/runtime.py's ReducedSimulator does.
 *
 * The arrays file: PATH.json, a JSON header whose "arrays" table gives each array's dtype,
 * shape and byte offset in PATH.bin (raw little-endian). Only what the step needs is read.
 */
#include "anisofem_reduced.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define ARRAYS_FORMAT "anisognn-arrays-1"
#define REDUCED_FORMAT "anisofem-reduced-1"
#define FLOOR 1.0
#define ARMIJO 1e-4
#define SMALLEST_STEP 1e-12
#define CLAMP 1e-8

struct af_reduced {
    int n, r;
    long triples;                /* T = r (r + 1) (r + 2) / 6 */
    double *rest, *basis, *masses, *c1, *C2, *S3, *W4;
    double *constant;            /* (r,) the projected constant force */
    double *work;                /* scratch for a step */
    int iterations;
};

static void say(char *error, size_t size, const char *fmt, const char *a, const char *b) {
    if (error && size) snprintf(error, size, fmt, a, b);
}

static char *read_file(const char *path, long *length) {
    FILE *f = fopen(path, "rb");
    char *data;
    long size;
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) != 0 || (size = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) {
        fclose(f);
        return NULL;
    }
    data = malloc((size_t)size + 1);
    if (data && fread(data, 1, (size_t)size, f) != (size_t)size) {
        free(data);
        data = NULL;
    }
    fclose(f);
    if (data) data[size] = '\0';
    if (length) *length = size;
    return data;
}

/* The text after `"key"` and its colon, searching from start; NULL if absent. */
static const char *value_of(const char *start, const char *key) {
    size_t k = strlen(key);
    const char *p = start;
    while ((p = strchr(p, '"')) != NULL) {
        if (strncmp(p + 1, key, k) == 0 && p[k + 1] == '"') {
            const char *c = p + k + 2;
            while (*c == ' ' || *c == '\n' || *c == '\r' || *c == '\t') c++;
            if (*c == ':') {
                c++;
                while (*c == ' ' || *c == '\n' || *c == '\r' || *c == '\t') c++;
                return c;
            }
        }
        p++;
    }
    return NULL;
}

/* Copy a JSON string value (at its opening quote) into out; 0 if it is not one. */
static int string_value(const char *v, char *out, size_t size) {
    size_t i = 0;
    if (!v || *v != '"') return 0;
    for (v++; *v && *v != '"' && i + 1 < size; v++) out[i++] = *v;
    out[i] = '\0';
    return *v == '"';
}

typedef struct { long shape[3]; int dims; long offset; } spec;

/* The spec of array `name` in the header's arrays table (from `table`); 0 if missing or not
 * float64. */
static int array_spec(const char *table, const char *name, spec *s) {
    const char *obj = value_of(table, name), *end, *v;
    char dtype[16];
    if (!obj || *obj != '{' || !(end = strchr(obj, '}'))) return 0;
    v = value_of(obj, "dtype");
    if (!v || v > end || !string_value(v, dtype, sizeof dtype) || strcmp(dtype, "float64"))
        return 0;
    v = value_of(obj, "offset");
    if (!v || v > end) return 0;
    s->offset = strtol(v, NULL, 10);
    v = value_of(obj, "shape");
    if (!v || v > end || *v != '[') return 0;
    s->dims = 0;
    v++;
    while (*v && *v != ']' && s->dims < 3) {
        char *next;
        s->shape[s->dims++] = strtol(v, &next, 10);
        v = next;
        while (*v == ',' || *v == ' ' || *v == '\n' || *v == '\r' || *v == '\t') v++;
    }
    return *v == ']';
}

static long count(const spec *s) {
    long c = 1;
    int i;
    for (i = 0; i < s->dims; i++) c *= s->shape[i];
    return c;
}

/* Read array `name` (+ tag) of the expected dims into a new buffer; NULL with a message. */
static double *load_array(const char *table, const char *bin, long bin_size, const char *name,
                          const char *tag, int dims, spec *s, char *error, size_t size) {
    char key[96];
    double *out;
    snprintf(key, sizeof key, "%s%s", name, tag);
    if (!array_spec(table, key, s) || s->dims != dims) {
        say(error, size, "the arrays file has no float64 array %s of the expected rank%s", key, "");
        return NULL;
    }
    if (s->offset < 0 || s->offset + count(s) * 8 > bin_size) {
        say(error, size, "array %s runs past the end of the .bin file%s", key, "");
        return NULL;
    }
    out = malloc((size_t)count(s) * sizeof(double));
    if (out) memcpy(out, bin + s->offset, (size_t)count(s) * sizeof(double));
    else say(error, size, "no memory for array %s%s", key, "");
    return out;
}

void af_reduced_free(af_reduced *m) {
    if (!m) return;
    free(m->rest); free(m->basis); free(m->masses); free(m->c1); free(m->C2); free(m->S3);
    free(m->W4); free(m->work); free(m->constant);
    free(m);
}

af_reduced *af_reduced_load(const char *path, const char *angle, char *error,
                            size_t error_size) {
    char name[4096], text[128], tag[64] = "";
    char *json, *bin = NULL;
    const char *table, *v;
    long bin_size = 0, r;
    spec s;
    af_reduced *m;
    snprintf(name, sizeof name, "%s.json", path);
    json = read_file(name, NULL);
    if (!json) {
        say(error, error_size, "path: cannot read %s (%s)", name, strerror(errno));
        return NULL;
    }
    if (!string_value(value_of(json, "format"), text, sizeof text)
        || strcmp(text, ARRAYS_FORMAT) != 0) {
        say(error, error_size, "path: %s is not an arrays header (format %s)", name, text);
        free(json);
        return NULL;
    }
    if (!string_value(value_of(json, "model_format"), text, sizeof text)
        || strcmp(text, REDUCED_FORMAT) != 0) {
        say(error, error_size, "path: %s holds model_format '%s', and this runtime reads "
            "'" REDUCED_FORMAT "'; rebuild the file with this version's python -m export "
            "reduced", name, text);
        free(json);
        return NULL;
    }
    if (angle) snprintf(tag, sizeof tag, "@%s", angle);
    table = value_of(json, "arrays");
    v = value_of(json, "bin");
    if (!table || !string_value(v, text, sizeof text)) {
        say(error, error_size, "path: %s has no arrays table or bin file name%s", name, "");
        free(json);
        return NULL;
    }
    {   /* the .bin next to the .json */
        const char *slash = strrchr(path, '/');
        int dir = slash ? (int)(slash - path + 1) : 0;
        snprintf(name, sizeof name, "%.*s%s", dir, path, text);
    }
    bin = read_file(name, &bin_size);
    m = calloc(1, sizeof *m);
    if (!bin || !m) {
        say(error, error_size, "path: cannot read %s (%s)", name, bin ? "no memory" : strerror(errno));
        free(json); free(bin); free(m);
        return NULL;
    }
    if (!(m->rest = load_array(table, bin, bin_size, "rest_positions", "", 2, &s, error, error_size)))
        goto fail;
    m->n = (int)s.shape[0];
    if (!(m->masses = load_array(table, bin, bin_size, "masses", "", 1, &s, error, error_size)))
        goto fail;
    if (!(m->basis = load_array(table, bin, bin_size, "basis", tag, 3, &s, error, error_size)))
        goto fail;
    r = m->r = (int)s.shape[2];
    if (s.shape[0] != m->n || s.shape[1] != 3) {
        say(error, error_size, "basis%s: shape is not (n, 3, r)%s", tag, "");
        goto fail;
    }
    if (!(m->c1 = load_array(table, bin, bin_size, "c1", tag, 1, &s, error, error_size)))
        goto fail;
    if (!(m->C2 = load_array(table, bin, bin_size, "C2", tag, 2, &s, error, error_size)))
        goto fail;
    if (!(m->S3 = load_array(table, bin, bin_size, "S3", tag, 3, &s, error, error_size)))
        goto fail;
    if (!(m->W4 = load_array(table, bin, bin_size, "W4", tag, 2, &s, error, error_size)))
        goto fail;
    m->triples = r * (r + 1) * (r + 2) / 6;
    if (s.shape[0] != m->triples || s.shape[1] != r) {
        say(error, error_size, "W4%s: shape is not (r (r + 1) (r + 2) / 6, r)%s", tag, "");
        goto fail;
    }
    /* work: A, Ap (T each); X, Y, H, L, V, J (r^2 each); g, p, x, load, terms, t1, lam (r
       each) */
    m->work = malloc((size_t)(2 * m->triples + 6 * r * r + 7 * r) * sizeof(double));
    m->constant = calloc((size_t)r, sizeof(double));
    if (!m->work || !m->constant) {
        say(error, error_size, "no memory for a model of r = %s%s", "", "");
        goto fail;
    }
    free(json);
    free(bin);
    return m;
fail:
    free(json);
    free(bin);
    af_reduced_free(m);
    return NULL;
}

int af_reduced_vertices(const af_reduced *m) { return m->n; }
int af_reduced_coordinates(const af_reduced *m) { return m->r; }
const double *af_reduced_masses(const af_reduced *m) { return m->masses; }
const double *af_reduced_rest_positions(const af_reduced *m) { return m->rest; }
int af_reduced_iterations(const af_reduced *m) { return m->iterations; }

void af_reduced_positions(const af_reduced *m, const double *q, double *x) {
    long i, k, r = m->r;
    for (i = 0; i < 3L * m->n; i++) {
        double s = 0.0;
        const double *row = m->basis + i * r;
        for (k = 0; k < r; k++) s += row[k] * q[k];
        x[i] = m->rest[i] + s;
    }
}

/* a . b over r numbers, in four interleaved partial sums (independent chains the compiler
 * can pipeline and vectorize without reassociating), added pairwise at the end. */
static double dot(const double *a, const double *b, long r) {
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

/* out (T,) = W4 v */
static void w4_times(const af_reduced *m, const double *v, double *out) {
    long t, r = m->r;
    for (t = 0; t < m->triples; t++) out[t] = dot(m->W4 + t * r, v, r);
}

/* X[a, b] = sum_c T[a, b, c] u_c (r x r) for the symmetric T whose sorted triples a <= b <= c
 * are A (T,) in W4's row order: each sorted triple adds to the upper triangle once for each
 * distinct index it can give up to u; the lower triangle is mirrored. */
static void contract(const double *A, const double *u, double *X, long r) {
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
    for (ab = 0; ab < r * r; ab++) Y[ab] = dot(m->S3 + ab * r, u, r);
}

/* u^T M u for an r x r matrix M */
static double form(const double *M, const double *u, long r) {
    double s = 0.0;
    long a;
    for (a = 0; a < r; a++) s += u[a] * dot(M + a * r, u, r);
    return s;
}

/* Cholesky of H (r x r) into L (lower); 0 where H is not positive definite. */
static int cholesky(const double *H, double *L, long r) {
    long i, j, k;
    for (i = 0; i < r; i++)
        for (j = 0; j <= i; j++) {
            double s = H[i * r + j];
            for (k = 0; k < j; k++) s -= L[i * r + k] * L[j * r + k];
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

/* p = -H^-1 g by Cholesky, or with H's eigenvalues clamped to CLAMP of the largest. */
static void newton_direction(const double *H, const double *g, double *p, double *L,
                             double *V, double *lam, double *B, double *t1, long r) {
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
            double s = 0.0, floor_ = CLAMP * largest;
            for (k = 0; k < r; k++) s += V[k * r + i] * g[k];
            t1[i] = s / (lam[i] > floor_ ? lam[i] : floor_);
        }
        for (i = 0; i < r; i++) {
            double s = 0.0;
            for (k = 0; k < r; k++) s += V[i * r + k] * t1[k];
            p[i] = s;
        }
    }
    for (i = 0; i < r; i++) p[i] = -p[i];
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

static int finite_forces(const af_reduced *m, const double *force) {
    long i;
    for (i = 0; i < 3L * m->n; i++) if (!isfinite(force[i])) return 0;
    return 1;
}

int af_reduced_set_constant_force(af_reduced *m, const double *force) {
    long k;
    if (force && !finite_forces(m, force)) return AF_BAD_INPUT;
    for (k = 0; k < m->r; k++) m->constant[k] = 0.0;
    if (force) project(m, force, m->constant);
    return AF_OK;
}

int af_reduced_step(af_reduced *m, double *q, double *w, const double *force, double dt,
                    double rtol, int max_iter) {
    long r = m->r, rr = r * r, i, k, it;
    double *A = m->work, *Ap = A + m->triples, *X = Ap + m->triples, *Y = X + rr,
           *H = Y + rr, *L = H + rr, *V = L + rr, *J = V + rr, *g = J + rr, *p = g + r,
           *x = p + r, *load = x + r, *terms = load + r, *t1 = terms + r, *lam = t1 + r;
    double inertia, tolerance, residual = 0.0, eps = 2.220446049250313e-16;
    if (!(dt > 0.0) || !(rtol >= 0.0)) return AF_BAD_INPUT;
    if (force && !finite_forces(m, force)) return AF_BAD_INPUT;
    for (k = 0; k < r; k++) if (!isfinite(q[k]) || !isfinite(w[k])) return AF_BAD_INPUT;
    for (k = 0; k < r; k++) load[k] = m->constant[k];
    if (force) project(m, force, load);
    inertia = 1.0 / (dt * dt);
    tolerance = rtol * (sqrt(dot(load, load, r)) + sqrt(dot(w, w, r)) / dt);
    for (k = 0; k < r; k++) x[k] = q[k] + dt * w[k];
    w4_times(m, x, A);
    for (it = 0; it <= max_iter; it++) {
        double a1, a2, a3, pure, mixed, step = 1.0, floor_;
        contract(A, x, X, r);
        s3_times(m, x, Y);
        for (i = 0; i < r; i++) {
            double s = m->c1[i];
            for (k = 0; k < r; k++)
                s += (m->C2[i * r + k] + 3.0 * Y[i * r + k] + 4.0 * X[i * r + k]) * x[k];
            g[i] = s;
        }
        if (it == 0) tolerance += rtol * sqrt(dot(g, g, r));
        for (i = 0; i < r; i++) {
            g[i] += inertia * (x[i] - (q[i] + dt * w[i])) - load[i];
            for (k = 0; k < r; k++)
                H[i * r + k] = m->C2[i * r + k] + 6.0 * Y[i * r + k] + 12.0 * X[i * r + k]
                               + (i == k ? inertia : 0.0);
        }
        residual = sqrt(dot(g, g, r));
        if (!isfinite(residual)) return AF_NOT_CONVERGED;
        for (i = 0; i < r; i++) {
            double s = 0.0;
            for (k = 0; k < r; k++) s += fabs(H[i * r + k]) * fabs(x[k]);
            terms[i] = s + fabs(load[i]) + fabs(m->c1[i]);
        }
        floor_ = FLOOR * eps * (double)r * sqrt(dot(terms, terms, r));
        if (residual <= (tolerance > floor_ ? tolerance : floor_)) {
            for (k = 0; k < r; k++) {
                w[k] = (x[k] - q[k]) / dt;
                q[k] = x[k];
            }
            m->iterations = (int)it;
            return AF_OK;
        }
        if (it == max_iter) break;
        newton_direction(H, g, p, L, V, lam, J, t1, r);
        a1 = dot(g, p, r);
        if (!(a1 < 0.0)) break;
        a2 = 0.5 * form(H, p, r);
        w4_times(m, p, Ap);
        cubic_forms(A, Ap, p, r, &mixed, &pure);
        s3_times(m, p, Y);
        a3 = form(Y, p, r) + 4.0 * mixed;
        while (step * (a2 + step * (a3 + step * pure)) > -(1.0 - ARMIJO) * a1
               && step >= SMALLEST_STEP)
            step *= 0.5;
        if (step < SMALLEST_STEP) break;
        for (k = 0; k < r; k++) x[k] += step * p[k];
        for (k = 0; k < m->triples; k++) A[k] += step * Ap[k];
    }
    m->iterations = (int)it;
    return AF_NOT_CONVERGED;
}
