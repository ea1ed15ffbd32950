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

typedef struct { long shape[4]; int dims; long offset; } spec;

/* The spec of array `name` in the header's arrays table (from `table`); 0 if missing or not
 * of dtype `type`. */
static int array_spec(const char *table, const char *name, const char *type, spec *s) {
    const char *obj = value_of(table, name), *end, *v;
    char dtype[16];
    if (!obj || *obj != '{' || !(end = strchr(obj, '}'))) return 0;
    v = value_of(obj, "dtype");
    if (!v || v > end || !string_value(v, dtype, sizeof dtype) || strcmp(dtype, type))
        return 0;
    v = value_of(obj, "offset");
    if (!v || v > end) return 0;
    s->offset = strtol(v, NULL, 10);
    v = value_of(obj, "shape");
    if (!v || v > end || *v != '[') return 0;
    s->dims = 0;
    v++;
    while (*v && *v != ']' && s->dims < 4) {
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

/* Read array `name` (+ tag) of dtype `type` ("float64" or "int32", `width` bytes an entry)
 * and the expected dims into a new buffer; NULL with a message. */
static void *load_typed(const char *table, const char *bin, long bin_size, const char *name,
                        const char *tag, const char *type, long width, int dims, spec *s,
                        char *error, size_t size) {
    char key[96];
    void *out;
    snprintf(key, sizeof key, "%s%s", name, tag);
    if (!array_spec(table, key, type, s) || s->dims != dims) {
        say(error, size, "the arrays file has no %s array %s of the expected rank", type, key);
        return NULL;
    }
    if (s->offset < 0 || s->offset + count(s) * width > bin_size) {
        say(error, size, "array %s runs past the end of the .bin file%s", key, "");
        return NULL;
    }
    out = malloc((size_t)(count(s) * width) + 1);
    if (out) memcpy(out, bin + s->offset, (size_t)(count(s) * width));
    else say(error, size, "no memory for array %s%s", key, "");
    return out;
}

static double *load_array(const char *table, const char *bin, long bin_size, const char *name,
                          const char *tag, int dims, spec *s, char *error, size_t size) {
    return load_typed(table, bin, bin_size, name, tag, "float64", 8, dims, s, error, size);
}

void af_reduced_free(af_reduced *m) {
    if (!m) return;
    free(m->rest); free(m->basis); free(m->masses); free(m->c1); free(m->C2); free(m->S3);
    free(m->W4); free(m->work); free(m->constant);
    free(m);
}

/* Read PATH.json and the .bin it names into *json and *bin (bin_size bytes), checking the
 * arrays format and the model format `format` (`command` rebuilds a file of another); the
 * tag "@angle" (or "") into tag; a zeroed model of model_size bytes into *model; 0 with a
 * message, nothing left allocated. */
static int open_model(const char *path, const char *angle, const char *format,
                      const char *command, char **json, char **bin, long *bin_size, char *tag,
                      size_t tag_size, size_t model_size, void **model, char *error,
                      size_t error_size) {
    char name[4096], text[128], hint[256];
    const char *v;
    snprintf(name, sizeof name, "%s.json", path);
    *bin = NULL;
    *json = read_file(name, NULL);
    if (!*json) {
        say(error, error_size, "path: cannot read %s (%s)", name, strerror(errno));
        return 0;
    }
    if (!string_value(value_of(*json, "format"), text, sizeof text)
        || strcmp(text, ARRAYS_FORMAT) != 0) {
        say(error, error_size, "path: %s is not an arrays header (format %s)", name, text);
        goto fail;
    }
    if (!string_value(value_of(*json, "model_format"), text, sizeof text)
        || strcmp(text, format) != 0) {
        snprintf(hint, sizeof hint, "', and this runtime reads '%s'; rebuild the file with this "
                 "version's %s", format, command);
        say(error, error_size, "path: %s holds model_format '%s", name, text);
        if (error && error_size > strlen(error))
            strncat(error, hint, error_size - strlen(error) - 1);
        goto fail;
    }
    tag[0] = '\0';
    if (angle) snprintf(tag, tag_size, "@%s", angle);
    v = value_of(*json, "bin");
    if (!value_of(*json, "arrays") || !string_value(v, text, sizeof text)) {
        say(error, error_size, "path: %s has no arrays table or bin file name%s", name, "");
        goto fail;
    }
    {   /* the .bin next to the .json */
        const char *slash = strrchr(path, '/');
        int dir = slash ? (int)(slash - path + 1) : 0;
        snprintf(name, sizeof name, "%.*s%s", dir, path, text);
    }
    *bin = read_file(name, bin_size);
    if (!*bin) {
        say(error, error_size, "path: cannot read %s (%s)", name, strerror(errno));
        goto fail;
    }
    *model = calloc(1, model_size);
    if (*model) return 1;
    say(error, error_size, "no memory for a model%s%s", "", "");
    free(*bin);
    *bin = NULL;
fail:
    free(*json);
    *json = NULL;
    return 0;
}

af_reduced *af_reduced_load(const char *path, const char *angle, char *error,
                            size_t error_size) {
    char tag[64];
    char *json, *bin;
    const char *table;
    long bin_size = 0, r;
    spec s;
    af_reduced *m;
    if (!open_model(path, angle, REDUCED_FORMAT, "python -m export reduced", &json, &bin,
                    &bin_size, tag, sizeof tag, sizeof *m, (void **)&m, error, error_size))
        return NULL;
    table = value_of(json, "arrays");
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
    long i, j;
    for (i = 0; i < r; i++)
        for (j = 0; j <= i; j++) {
            double s = H[i * r + j] - dot(L + i * r, L + j * r, j);
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
static void newton_direction(const double *H, const double *g, double *p, double *L,
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
        newton_direction(H, g, p, L, V, lam, J, t1, r, CLAMP, 0);
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

/* ---------------------------------------------------------------------------------------
 * The framed model (`python -m export reduced --framed`): export/framed_runtime.py's
 * FramedSimulator, the same step in the same order. Domain d's node i sits at
 * R_d (y_i + U_i q_d) + c_d; a step is Newton over each domain's own move t, turn theta and
 * coordinates q, the centres carried along the domains' kinematic tree.
 */
#define FRAMED_FORMAT "anisofem-framed-1"
#define STEP_TOLERANCE 1e-8
#define MIRROR_FLOOR 1e-10

struct af_framed {
    int n, D, Q, Z, rmax, joints, points, k, nodes, pairs, links;
    int nf, dk;                /* the model's nodes; model nodes per display vertex (0: none) */
    int *display_nodes;        /* (n, dk): each vertex's model nodes, where a display mesh */
    double *display_weights;   /* (n, dk): their weights */
    double *x0, *spread;       /* the model nodes' rest positions; forces spread on them */
    double size;
    int *labels, *r, *q0, *z0, *b0, *parent, *order, *chain, *poly;
    int *joint_nodes, *joint_labels, *joint_tets, *pair_list, *pair_ptr, *element_pairs;
    double *rest, *masses, *Y, *U, *centre, *mass, *a, *J, *A, *B, *radius, *reach;
    double *c0, *c1, *C2, *S3, *W4, *arm_parent, *arm_own, *arms;
    double *grads, *weights, *mu, *lam, *kappa, *fiber;
    double *constant;          /* the constant force's moments: T0 (9 D), T (9 Q), t (3 D) */
    double *work;
    int iterations;
};

void af_framed_free(af_framed *m) {
    if (!m) return;
    free(m->labels); free(m->r); free(m->q0); free(m->z0); free(m->b0); free(m->parent);
    free(m->order); free(m->chain); free(m->poly); free(m->joint_nodes); free(m->joint_labels);
    free(m->joint_tets); free(m->pair_list); free(m->pair_ptr); free(m->element_pairs);
    free(m->rest); free(m->masses); free(m->Y); free(m->U); free(m->centre); free(m->mass);
    free(m->a); free(m->J); free(m->A); free(m->B); free(m->radius); free(m->reach);
    free(m->c0); free(m->c1); free(m->C2); free(m->S3); free(m->W4); free(m->arm_parent);
    free(m->arm_own); free(m->arms); free(m->grads); free(m->weights); free(m->mu);
    free(m->lam); free(m->kappa); free(m->fiber); free(m->constant); free(m->work);
    free(m->display_nodes); free(m->display_weights); free(m->spread);
    if (m->x0 != m->rest) free(m->x0);
    free(m);
}

static int compare_longs(const void *x, const void *y) {
    long a = *(const long *)x, b = *(const long *)y;
    return (a > b) - (a < b);
}

/* The joints' compact node numbering, their node pairs and each element's pairs. */
static int plan_joints(af_framed *m, const int *tets) {
    long e, a, b, i, total = (long)m->joints * m->k, count = 0, unique = 0;
    long *keys = malloc((size_t)(total > 0 ? total : 1) * sizeof(long) * (size_t)m->k);
    int *local = malloc((size_t)m->nf * sizeof(int));
    if (!keys || !local) { free(keys); free(local); return 0; }
    for (i = 0; i < m->nf; i++) local[i] = -1;
    for (e = 0; e < total; e++) local[tets[e]] = 0;
    m->nodes = 0;
    for (i = 0; i < m->nf; i++) if (local[i] == 0) local[i] = m->nodes++;
    m->joint_nodes = malloc((size_t)m->nodes * sizeof(int) + 1);
    m->joint_labels = malloc((size_t)m->nodes * sizeof(int) + 1);
    m->joint_tets = malloc((size_t)total * sizeof(int) + 1);
    if (!m->joint_nodes || !m->joint_labels || !m->joint_tets) { free(keys); free(local); return 0; }
    for (i = 0; i < m->nf; i++)
        if (local[i] >= 0) { m->joint_nodes[local[i]] = (int)i; m->joint_labels[local[i]] = m->labels[i]; }
    for (e = 0; e < total; e++) m->joint_tets[e] = local[tets[e]];
    for (e = 0; e < m->joints; e++)
        for (a = 0; a < m->k; a++)
            for (b = 0; b < m->k; b++)
                keys[count++] = (long)m->joint_tets[e * m->k + a] * m->nodes
                                + m->joint_tets[e * m->k + b];
    qsort(keys, (size_t)count, sizeof(long), compare_longs);
    for (i = 0; i < count; i++) if (i == 0 || keys[i] != keys[i - 1]) keys[unique++] = keys[i];
    m->pairs = (int)unique;
    m->pair_list = malloc((size_t)(2 * unique) * sizeof(int) + 1);
    m->pair_ptr = calloc((size_t)m->nodes + 1, sizeof(int));
    m->element_pairs = malloc((size_t)(count > 0 ? count : 1) * sizeof(int));
    if (!m->pair_list || !m->pair_ptr || !m->element_pairs) { free(keys); free(local); return 0; }
    for (i = 0; i < unique; i++) {
        m->pair_list[2 * i] = (int)(keys[i] / m->nodes);
        m->pair_list[2 * i + 1] = (int)(keys[i] % m->nodes);
        m->pair_ptr[m->pair_list[2 * i] + 1]++;
    }
    for (i = 0; i < m->nodes; i++) m->pair_ptr[i + 1] += m->pair_ptr[i];
    for (e = 0; e < m->joints; e++)
        for (a = 0; a < m->k; a++)
            for (b = 0; b < m->k; b++) {
                long key = (long)m->joint_tets[e * m->k + a] * m->nodes + m->joint_tets[e * m->k + b];
                long *hit = bsearch(&key, keys, (size_t)unique, sizeof(long), compare_longs);
                m->element_pairs[(e * m->k + a) * m->k + b] = (int)(hit - keys);
            }
    free(keys);
    free(local);
    return 1;
}

#define F64(field, name, dims) \
    if (!(m->field = load_typed(table, bin, bin_size, name, tag, "float64", 8, dims, &s, error, \
                                error_size))) goto fail
#define I32(field, name, dims) \
    if (!(m->field = load_typed(table, bin, bin_size, name, tag, "int32", 4, dims, &s, error, \
                                error_size))) goto fail

/* A display mesh's arrays where the file has them (display_nodes, display_weights,
 * physics_rest: each of the n vertices a weighted sum of the model's nf nodes), else the
 * vertices are the model's nodes. 0 with the reason in error where they do not fit. */
static int load_display(af_framed *m, const char *table, const char *bin, long bin_size,
                        char *error, size_t error_size) {
    spec s;
    long i;
    m->x0 = m->rest;
    if (!array_spec(table, "display_nodes", "int32", &s)) {
        if (m->nf == m->n) return 1;
        say(error, error_size, "labels: one per vertex expected, or a display mesh's "
            "display_nodes%s%s", "", "");
        return 0;
    }
    if (!(m->display_nodes = load_typed(table, bin, bin_size, "display_nodes", "", "int32", 4, 2,
                                        &s, error, error_size))) return 0;
    m->dk = (int)s.shape[1];
    if (s.shape[0] != m->n) {
        say(error, error_size, "display_nodes: one row per vertex expected%s%s", "", "");
        return 0;
    }
    for (i = 0; i < (long)m->n * m->dk; i++)
        if (m->display_nodes[i] < 0 || m->display_nodes[i] >= m->nf) {
            say(error, error_size, "display_nodes: a node outside the model's labels%s%s", "", "");
            return 0;
        }
    if (!(m->display_weights = load_typed(table, bin, bin_size, "display_weights", "", "float64",
                                          8, 2, &s, error, error_size))) return 0;
    if (!(m->x0 = load_typed(table, bin, bin_size, "physics_rest", "", "float64", 8, 2, &s,
                             error, error_size))) return 0;
    if (s.shape[0] != m->nf) {
        say(error, error_size, "physics_rest: one row per model node expected%s%s", "", "");
        return 0;
    }
    if (!(m->spread = malloc((size_t)(3L * m->nf) * sizeof(double)))) {
        say(error, error_size, "no memory for a model%s%s", "", "");
        return 0;
    }
    return 1;
}

af_framed *af_framed_load(const char *path, const char *angle, char *error, size_t error_size) {
    char tag[64];
    char *json, *bin;
    const char *table, *v;
    long bin_size = 0, d, q = 0, z = 0, b = 0, P, width;
    int *tets = NULL;
    spec s;
    af_framed *m;
    if (!open_model(path, angle, FRAMED_FORMAT, "python -m export reduced --framed", &json,
                    &bin, &bin_size, tag, sizeof tag, sizeof *m, (void **)&m, error,
                    error_size))
        return NULL;
    table = value_of(json, "arrays");
    v = value_of(json, "size");
    m->size = v ? strtod(v, NULL) : 0.0;
    {   /* the mesh arrays carry no tag */
        const char *none = "";
        if (!(m->rest = load_typed(table, bin, bin_size, "rest_positions", none, "float64", 8, 2,
                                   &s, error, error_size))) goto fail;
        m->n = (int)s.shape[0];
        if (!(m->masses = load_typed(table, bin, bin_size, "masses", none, "float64", 8, 1, &s,
                                     error, error_size))) goto fail;
    }
    I32(labels, "labels", 1);
    m->nf = (int)s.shape[0];
    if (!load_display(m, table, bin, bin_size, error, error_size)) goto fail;
    I32(r, "r", 1);
    m->D = (int)s.shape[0];
    F64(Y, "Y", 2);
    F64(U, "U", 3);
    m->rmax = (int)s.shape[2];
    F64(centre, "centre", 2); F64(mass, "mass", 1); F64(a, "a", 1); F64(J, "J", 3);
    F64(A, "A", 3); F64(B, "B", 3); F64(radius, "radius", 1); F64(reach, "reach", 1);
    F64(c0, "c0", 1); F64(c1, "c1", 1); F64(C2, "C2", 1); F64(S3, "S3", 1); F64(W4, "W4", 1);
    I32(poly, "poly_offsets", 2);
    I32(parent, "parent", 1); I32(order, "order", 1);
    F64(arm_parent, "arm_parent", 2); F64(arm_own, "arm_own", 2);
    I32(chain, "chain", 2);
    P = s.shape[0];
    F64(arms, "arms", 2);
    F64(grads, "joint_grads", 4);
    m->joints = (int)s.shape[0]; m->points = (int)s.shape[1]; m->k = (int)s.shape[2];
    F64(weights, "joint_weights", 2); F64(mu, "mu", 1); F64(lam, "lam", 1);
    F64(kappa, "kappa", 1); F64(fiber, "fiber", 2);
    if (!(tets = load_typed(table, bin, bin_size, "joint_tets", tag, "int32", 4, 2, &s, error,
                            error_size))) goto fail;
    for (d = 0; d < (long)m->joints * m->k; d++)
        if (tets[d] < 0 || tets[d] >= m->nf) {
            say(error, error_size, "joint_tets: a node outside the model's labels%s%s", "", "");
            goto fail;
        }
    if (m->D > 64 || m->k > 16 || m->dk > 16) {
        say(error, error_size, "path: this runtime steps at most 64 domains and 16 nodes an "
            "element%s%s", "", "");
        goto fail;
    }
    m->links = (int)P;
    m->q0 = malloc((size_t)m->D * sizeof(int)); m->z0 = malloc((size_t)m->D * sizeof(int));
    m->b0 = malloc((size_t)m->D * sizeof(int));
    if (!m->q0 || !m->z0 || !m->b0 || !plan_joints(m, tets)) {
        say(error, error_size, "no memory for a model%s%s", "", "");
        goto fail;
    }
    for (d = 0; d < m->D; d++) {
        m->q0[d] = (int)q; m->z0[d] = (int)z; m->b0[d] = (int)b;
        q += m->r[d]; z += 6 + m->r[d]; b += (long)m->r[d] * m->r[d];
    }
    m->Q = (int)q; m->Z = (int)z;
    width = 6 + m->rmax;
    {   /* work: the scratch of af_framed_step (framed_scratch) */
        long Z = m->Z, D = m->D, nodes = m->nodes, rm = m->rmax;
        size_t doubles = (size_t)(7 * Z * Z + 2 * 3 * D * Z + 8 * Z
                                  + 3 * nodes * (2 + 3 * width) + 9 * (long)m->pairs
                                  + 9 * D + 9 * m->Q + 3 * D + 5 * (12 * D + m->Q) + 9 * D
                                  + (rm + 2) * (rm + 2) * (rm + 2) / 6 * 2 + 3 * rm * rm
                                  + 4 * rm + 256);
        m->work = malloc(doubles * sizeof(double));
        m->constant = calloc((size_t)(9 * D + 9 * m->Q + 3 * D), sizeof(double));
        if (!m->work || !m->constant) {
            say(error, error_size, "no memory for a model%s%s", "", "");
            goto fail;
        }
    }
    free(tets); free(json); free(bin);
    return m;
fail:
    free(tets); free(json); free(bin);
    af_framed_free(m);
    return NULL;
}
#undef F64
#undef I32

int af_framed_vertices(const af_framed *m) { return m->n; }
int af_framed_state_size(const af_framed *m) { return 12 * m->D + m->Q + 12; }
const double *af_framed_masses(const af_framed *m) { return m->masses; }
const double *af_framed_rest_positions(const af_framed *m) { return m->rest; }
int af_framed_iterations(const af_framed *m) { return m->iterations; }

static void framed_moments(const af_framed *m, const double *force, double *T0, double *T,
                           double *t);

int af_framed_set_constant_force(af_framed *m, const double *force) {
    long i, count = 9L * m->D + 9L * m->Q + 3L * m->D;
    if (force) for (i = 0; i < 3L * m->n; i++) if (!isfinite(force[i])) return AF_BAD_INPUT;
    for (i = 0; i < count; i++) m->constant[i] = 0.0;
    if (force)
        framed_moments(m, force, m->constant, m->constant + 9L * m->D,
                       m->constant + 9L * m->D + 9L * m->Q);
    return AF_OK;
}

/* the base of a state: [R_g (9, row-major) | c_g (3)] after its coordinates */
#define BASE(m, st) ((st) + 12 * (m)->D + (m)->Q)

void af_framed_rest_state(const af_framed *m, double *state) {
    long d, i;
    for (i = 0; i < 12L * m->D + m->Q + 12; i++) state[i] = 0.0;
    for (d = 0; d < m->D; d++) {
        for (i = 0; i < 3; i++) state[3 * d + i] = m->centre[3 * d + i];
        for (i = 0; i < 3; i++) state[3 * m->D + 9 * d + 4 * i] = 1.0;
    }
    for (i = 0; i < 3; i++) BASE(m, state)[4 * i] = 1.0;
}

/* positions (3 per node) of `nodes` (count of them; all where NULL) into out */
static void framed_positions(const af_framed *m, const double *st, const int *nodes, long count,
                             double *out) {
    const double *c = st, *R = st + 3 * m->D, *q = st + 12 * m->D, *base = BASE(m, st);
    long k, a, b;
    for (k = 0; k < count; k++) {
        long i = nodes ? nodes[k] : k;
        int d = m->labels[i];
        double y[3];
        if (d < 0) {  /* held: carried by the base */
            const double *x0 = m->x0 + 3 * i;
            for (a = 0; a < 3; a++)
                out[3 * k + a] = base[3 * a] * x0[0] + base[3 * a + 1] * x0[1]
                                 + base[3 * a + 2] * x0[2] + base[9 + a];
            continue;
        }
        for (a = 0; a < 3; a++) {
            const double *row = m->U + (3 * i + a) * m->rmax;
            double v = m->Y[3 * i + a];
            for (b = 0; b < m->r[d]; b++) v += row[b] * q[m->q0[d] + b];
            y[a] = v;
        }
        for (a = 0; a < 3; a++) {
            const double *Ra = R + 9 * d + 3 * a;
            out[3 * k + a] = Ra[0] * y[0] + Ra[1] * y[1] + Ra[2] * y[2] + c[3 * d + a];
        }
    }
}

void af_framed_positions(const af_framed *m, const double *state, double *x) {
    long i, k, a;
    double p[3 * 16];
    if (!m->display_nodes) {
        framed_positions(m, state, NULL, m->n, x);
        return;
    }
    for (i = 0; i < m->n; i++) {  /* each display vertex from its model nodes */
        const double *w = m->display_weights + i * m->dk;
        framed_positions(m, state, m->display_nodes + i * m->dk, m->dk, p);
        for (a = 0; a < 3; a++) {
            double v = 0.0;
            for (k = 0; k < m->dk; k++) v += w[k] * p[3 * k + a];
            x[3 * i + a] = v;
        }
    }
}

/* out[0..9] += w R M for 3 x 3 R, M */
static void add_product(double w, const double *R, const double *M, double *out) {
    int i, j;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++)
            out[3 * i + j] += w * (R[3 * i] * M[j] + R[3 * i + 1] * M[3 + j]
                                   + R[3 * i + 2] * M[6 + j]);
}

/* T0 (9 D), T (9 Q), t (3 D) += the moments of nodal forces force (n x 3) */
static void framed_moments(const af_framed *m, const double *force, double *T0, double *T,
                           double *t) {
    long i, a, b, c, d;
    if (m->display_nodes) {  /* each display vertex's force spread on its model nodes */
        for (i = 0; i < 3L * m->nf; i++) m->spread[i] = 0.0;
        for (i = 0; i < m->n; i++)
            for (c = 0; c < m->dk; c++) {
                long node = m->display_nodes[i * m->dk + c];
                double w = m->display_weights[i * m->dk + c];
                for (a = 0; a < 3; a++) m->spread[3 * node + a] += w * force[3 * i + a];
            }
        force = m->spread;
    }
    for (i = 0; i < m->nf; i++) {
        d = m->labels[i];
        if (d < 0) continue;
        for (a = 0; a < 3; a++) {
            double f = force[3 * i + a];
            if (f == 0.0) continue;    /* a drag or an actuator pushes a few nodes */
            t[3 * d + a] += f;
            for (b = 0; b < 3; b++) {
                const double *row = m->U + (3 * i + b) * m->rmax;
                T0[9 * d + 3 * a + b] += f * m->Y[3 * i + b];
                for (c = 0; c < m->r[d]; c++) T[9 * (m->q0[d] + c) + 3 * a + b] += f * row[c];
            }
        }
    }
}

/* the targets T0 (9 D), T (9 Q), t (3 D): the constant force's and force's moments (force
 * NULL: none) plus the inertia's pull towards x_hat = 2 x(now) - x(before) */
static void framed_targets(const af_framed *m, const double *now, const double *before,
                           const double *force, double inertia, double *T0, double *T,
                           double *t) {
    long i, a, b, c, k, d;
    double M[9];
    const double *K0 = m->constant, *K = K0 + 9L * m->D, *Kt = K + 9L * m->Q;
    for (i = 0; i < 9L * m->D; i++) T0[i] = K0[i];
    for (i = 0; i < 9L * m->Q; i++) T[i] = K[i];
    for (i = 0; i < 3L * m->D; i++) t[i] = Kt[i];
    if (force) framed_moments(m, force, T0, T, t);
    for (k = 0; k < 2; k++) {
        const double *st = k == 0 ? now : before;
        const double *R = st + 3 * m->D, *q = st + 12 * m->D;
        double w = inertia * (k == 0 ? 2.0 : -1.0);
        for (d = 0; d < m->D; d++) {
            long r = m->r[d], q0 = m->q0[d];
            for (i = 0; i < 9; i++) {
                double v = m->J[9 * d + i];
                for (a = 0; a < r; a++) v += q[q0 + a] * m->A[9 * (q0 + a) + i];
                M[i] = v;
            }
            add_product(w, R + 9 * d, M, T0 + 9 * d);
            for (b = 0; b < r; b++) {
                for (i = 0; i < 3; i++)
                    for (c = 0; c < 3; c++) {
                        double v = m->A[9 * (q0 + b) + 3 * c + i];
                        for (a = 0; a < r; a++)
                            v += q[q0 + a] * m->B[9 * (m->b0[d] + a * r + b) + 3 * i + c];
                        M[3 * i + c] = v;
                    }
                add_product(w, R + 9 * d, M, T + 9 * (q0 + b));
            }
            for (i = 0; i < 3; i++) t[3 * d + i] += w * m->mass[d] * st[3 * d + i];
        }
    }
}

/* G[j] = [e_j]_x R (9 each) */
static void turned(const double *R, double G[3][9]) {
    int b;
    for (b = 0; b < 9; b++) G[0][b] = G[1][b] = G[2][b] = 0.0;
    for (b = 0; b < 3; b++) {
        double r0 = R[b], r1 = R[3 + b], r2 = R[6 + b];
        G[0][3 + b] = -r2; G[0][6 + b] = r1;
        G[1][b] = r2; G[1][6 + b] = -r0;
        G[2][b] = -r1; G[2][3 + b] = r0;
    }
}

/* out = [e_i]_x M (9) */
static void cross_with(int i, const double *M, double *out) {
    int b;
    for (b = 0; b < 9; b++) out[b] = 0.0;
    for (b = 0; b < 3; b++) {
        if (i == 0) { out[3 + b] = -M[6 + b]; out[6 + b] = M[3 + b]; }
        if (i == 1) { out[b] = M[6 + b]; out[6 + b] = -M[b]; }
        if (i == 2) { out[b] = -M[3 + b]; out[3 + b] = M[b]; }
    }
}

static double sum9(const double *A, const double *B) {
    double s = 0.0;
    int k;
    for (k = 0; k < 9; k++) s += A[k] * B[k];
    return s;
}

/* The quartic of domain d at q (r,): its energy; with g, its gradient (r,) and Hessian (r, r)
 * into g and H (row stride r). scratch: triples + 2 r^2 doubles. */
static double domain_quartic(const af_framed *m, int d, const double *q, double *g, double *H,
                             double *scratch) {
    long r = m->r[d], T = r * (r + 1) * (r + 2) / 6, a, b;
    const int *o = m->poly + 3 * d;
    const double *c1 = m->c1 + m->q0[d], *C2 = m->C2 + o[0], *S3 = m->S3 + o[1];
    const double *W4 = m->W4 + o[2];
    double *A = scratch, *X = A + T, *Y = X + r * r, E = m->c0[d];
    for (a = 0; a < T; a++) A[a] = dot(W4 + a * r, q, r);
    contract(A, q, X, r);
    for (a = 0; a < r * r; a++) Y[a] = dot(S3 + a * r, q, r);
    for (a = 0; a < r; a++) {
        double Cq = 0.0, Yq = 0.0, Xq = 0.0;
        for (b = 0; b < r; b++) {
            Cq += C2[a * r + b] * q[b];
            Yq += Y[a * r + b] * q[b];
            Xq += X[a * r + b] * q[b];
            if (g) H[a * r + b] = C2[a * r + b] + 6.0 * Y[a * r + b] + 12.0 * X[a * r + b];
        }
        E += q[a] * (c1[a] + 0.5 * Cq + Yq + Xq);
        if (g) g[a] = c1[a] + Cq + 3.0 * Yq + 4.0 * Xq;
    }
    return E;
}

typedef struct {
    double *T0, *T, *t;        /* targets */
    double *x, *grad, *blocks, *Jn, *K, *quartic, *gq, *Hq;
    double *Hs;                /* the joints' Gauss-Newton part, upper triangle (Z, Z) */
} framed_scratch;

/* The joints' StVK plus fiber energy at their nodes' positions x; with g, their gradient and
 * Hessian chained through each node's frame added to g and H (Z, Z). */
static double joint_terms(const af_framed *m, const double *st, framed_scratch *w, double *g,
                          double *H) {
    long e, p, a, b, i, j, l, k = m->k, Z = m->Z, width = 6 + m->rmax;
    const double *c = st, *R = st + 3 * m->D;
    const double *x = w->x;
    double F[9], S[9], FF[9], Fd[3], qa[3 * 16], sd[16], E = 0.0;
    if (g) {
        for (i = 0; i < 3L * m->nodes; i++) w->grad[i] = 0.0;
        for (i = 0; i < 9L * m->pairs; i++) w->blocks[i] = 0.0;
    }
    for (e = 0; e < m->joints; e++) {
        double mu = m->mu[e], lam = m->lam[e], kappa = m->kappa[e];
        const double *d = m->fiber + 3 * e;
        for (p = 0; p < m->points; p++) {
            const double *G = m->grads + (e * m->points + p) * k * 3;
            double wt = m->weights[e * m->points + p], trE = 0.0, EE = 0.0, I4m1;
            for (i = 0; i < 9; i++) F[i] = 0.0;
            for (a = 0; a < k; a++) {
                long node = m->joint_tets[e * k + a];
                for (i = 0; i < 3; i++)
                    for (j = 0; j < 3; j++) F[3 * i + j] += x[3 * node + i] * G[3 * a + j];
            }
            for (i = 0; i < 3; i++)
                for (j = 0; j < 3; j++) {
                    double v = 0.0;
                    for (l = 0; l < 3; l++) v += F[3 * l + i] * F[3 * l + j];
                    S[3 * i + j] = 0.5 * (v - (i == j ? 1.0 : 0.0));
                }
            for (i = 0; i < 3; i++) trE += S[4 * i];
            for (i = 0; i < 9; i++) EE += S[i] * S[i];
            for (i = 0; i < 9; i++) S[i] *= 2.0 * mu;
            for (i = 0; i < 3; i++) S[4 * i] += lam * trE;
            for (i = 0; i < 3; i++) Fd[i] = F[3 * i] * d[0] + F[3 * i + 1] * d[1] + F[3 * i + 2] * d[2];
            I4m1 = Fd[0] * Fd[0] + Fd[1] * Fd[1] + Fd[2] * Fd[2] - 1.0;
            for (i = 0; i < 3; i++)
                for (j = 0; j < 3; j++) S[3 * i + j] += 4.0 * kappa * I4m1 * d[i] * d[j];
            E += wt * (0.5 * lam * trE * trE + mu * EE + kappa * I4m1 * I4m1);
            if (!g) continue;
            for (a = 0; a < k; a++) {
                long node = m->joint_tets[e * k + a];
                sd[a] = 0.0;
                for (i = 0; i < 3; i++) {
                    double v = 0.0, q_ = 0.0;
                    for (j = 0; j < 3; j++) q_ += F[3 * i + j] * G[3 * a + j];
                    qa[3 * a + i] = q_;
                    sd[a] += d[i] * G[3 * a + i];
                    for (j = 0; j < 3; j++) {
                        double SG = 0.0;
                        for (l = 0; l < 3; l++) SG += S[3 * j + l] * G[3 * a + l];
                        v += F[3 * i + j] * SG;
                    }
                    w->grad[3 * node + i] += wt * v;
                }
            }
            for (i = 0; i < 3; i++)
                for (l = 0; l < 3; l++) {
                    double v = 0.0;
                    for (j = 0; j < 3; j++) v += F[3 * i + j] * F[3 * l + j];
                    FF[3 * i + l] = v;
                }
            /* block (b, a) is block (a, b) transposed */
            for (a = 0; a < k; a++)
                for (b = a; b < k; b++) {
                    double GSG = 0.0, GG = 0.0, h[9];
                    double *ab = w->blocks + 9L * m->element_pairs[(e * k + a) * k + b];
                    double *ba = w->blocks + 9L * m->element_pairs[(e * k + b) * k + a];
                    for (i = 0; i < 3; i++) {
                        GG += G[3 * a + i] * G[3 * b + i];
                        for (j = 0; j < 3; j++) GSG += G[3 * a + i] * S[3 * i + j] * G[3 * b + j];
                    }
                    for (i = 0; i < 3; i++)
                        for (l = 0; l < 3; l++)
                            h[3 * i + l] = wt * ((i == l ? GSG : 0.0)
                                + mu * qa[3 * b + i] * qa[3 * a + l] + mu * FF[3 * i + l] * GG
                                + lam * qa[3 * a + i] * qa[3 * b + l]
                                + 8.0 * kappa * Fd[i] * Fd[l] * sd[a] * sd[b]);
                    for (i = 0; i < 9; i++) ab[i] += h[i];
                    if (b != a)
                        for (i = 0; i < 3; i++)
                            for (l = 0; l < 3; l++) ba[3 * l + i] += h[3 * i + l];
                }
        }
    }
    if (!g) return E;
    /* each node's Jacobian in its domain's unknowns: [I | -[w]_x | R U_i], w = x_i - c */
    for (i = 0; i < (long)m->nodes * 3 * width; i++) w->Jn[i] = 0.0;
    for (i = 0; i < Z * Z; i++) w->Hs[i] = 0.0;
    for (i = 0; i < m->nodes; i++) {
        int dd = m->joint_labels[i];
        double *Ji = w->Jn + 3 * i * width, wv[3];
        long node = m->joint_nodes[i];
        if (dd < 0) continue;
        for (a = 0; a < 3; a++) { wv[a] = x[3 * i + a] - c[3 * dd + a]; Ji[a * width + a] = 1.0; }
        Ji[4] = wv[2]; Ji[5] = -wv[1];
        Ji[width + 3] = -wv[2]; Ji[width + 5] = wv[0];
        Ji[2 * width + 3] = wv[1]; Ji[2 * width + 4] = -wv[0];
        for (a = 0; a < 3; a++)
            for (b = 0; b < m->r[dd]; b++) {
                double v = 0.0;
                for (l = 0; l < 3; l++) v += R[9 * dd + 3 * a + l] * m->U[(3 * node + l) * m->rmax + b];
                Ji[a * width + 6 + b] = v;
            }
    }
    for (i = 0; i < m->nodes; i++) {
        int dd = m->joint_labels[i], touched[64];
        long o, rd, u, v, ee;
        const double *gi = w->grad + 3 * i, *Ji = w->Jn + 3 * i * width;
        double wv[3], gw;
        if (dd < 0) continue;
        o = m->z0[dd]; rd = m->r[dd];
        for (a = 0; a < 3; a++) wv[a] = x[3 * i + a] - c[3 * dd + a];
        for (a = 0; a < 3; a++) g[o + a] += gi[a];
        g[o + 3] += wv[1] * gi[2] - wv[2] * gi[1];
        g[o + 4] += wv[2] * gi[0] - wv[0] * gi[2];
        g[o + 5] += wv[0] * gi[1] - wv[1] * gi[0];
        gw = gi[0] * wv[0] + gi[1] * wv[1] + gi[2] * wv[2];
        for (a = 0; a < 3; a++) {
            for (b = 0; b < 3; b++) H[(o + 3 + a) * Z + o + 3 + b] += 0.5 * (gi[a] * wv[b] + gi[b] * wv[a]);
            H[(o + 3 + a) * Z + o + 3 + a] -= gw;
        }
        for (b = 0; b < rd; b++) {
            double v0 = Ji[6 + b], v1 = Ji[width + 6 + b], v2 = Ji[2 * width + 6 + b];
            double cr[3] = {v1 * gi[2] - v2 * gi[1], v2 * gi[0] - v0 * gi[2], v0 * gi[1] - v1 * gi[0]};
            g[o + 6 + b] += v0 * gi[0] + v1 * gi[1] + v2 * gi[2];
            for (a = 0; a < 3; a++) {
                H[(o + 3 + a) * Z + o + 6 + b] += cr[a];
                H[(o + 6 + b) * Z + o + 3 + a] += cr[a];
            }
        }
        /* the Gauss-Newton part sum_j Jn_i^T h_ij Jn_j, symmetric: only towards domains
         * from node i's own on, and within it only the upper triangle (mirrored below) */
        for (ee = 0; ee < m->D; ee++) touched[ee] = 0;
        for (p = m->pair_ptr[i]; p < m->pair_ptr[i + 1]; p++) {
            long jj = m->pair_list[2 * p + 1], oj, nj;
            int dj = m->joint_labels[jj];
            if (dj < dd) continue;
            oj = m->z0[dj]; nj = 6 + m->r[dj];
            if (!touched[dj]) {
                touched[dj] = 1;
                for (a = 0; a < 3; a++) for (v = 0; v < nj; v++) w->K[a * Z + oj + v] = 0.0;
            }
            for (a = 0; a < 3; a++)
                for (b = 0; b < 3; b++) {
                    double h = w->blocks[9 * p + 3 * a + b];
                    const double *Jj = w->Jn + (3 * jj + b) * width;
                    for (v = 0; v < nj; v++) w->K[a * Z + oj + v] += h * Jj[v];
                }
        }
        for (ee = 0; ee < m->D; ee++) {
            long oe = m->z0[ee], ne = 6 + m->r[ee];
            if (!touched[ee]) continue;
            for (u = 0; u < 6 + rd; u++) {
                double j0 = Ji[u], j1 = Ji[width + u], j2 = Ji[2 * width + u];
                if (j0 == 0.0 && j1 == 0.0 && j2 == 0.0) continue;
                for (v = ee == dd ? u : 0; v < ne; v++)
                    w->Hs[(o + u) * Z + oe + v] += j0 * w->K[oe + v] + j1 * w->K[Z + oe + v]
                                                   + j2 * w->K[2 * Z + oe + v];
            }
        }
    }
    for (i = 0; i < Z; i++) {
        H[i * Z + i] += w->Hs[i * Z + i];
        for (j = i + 1; j < Z; j++) {
            H[i * Z + j] += w->Hs[i * Z + j];
            H[j * Z + i] += w->Hs[i * Z + j];
        }
    }
    return E;
}

/* The step's energy; with g, its gradient and Hessian (Z, Z) in each domain's centre, turn
 * about it and coordinates set into g and H. */
static double framed_energy(const af_framed *m, const double *st, framed_scratch *w,
                            double inertia, double *g, double *H) {
    long d, i, k, b, Z = m->Z;
    const double *c = st, *R = st + 3 * m->D, *q = st + 12 * m->D;
    double E = 0.0;
    if (g) {
        for (i = 0; i < Z; i++) g[i] = 0.0;
        for (i = 0; i < Z * Z; i++) H[i] = 0.0;
    }
    for (d = 0; d < m->D; d++) {
        long r = m->r[d], q0 = m->q0[d], o = m->z0[d];
        const double *Rd = R + 9 * d;
        double M[9], v = 0.0, GR[3][9], a9[9], b9[9];
        for (i = 0; i < 9; i++) M[i] = w->T0[9 * d + i];
        for (b = 0; b < r; b++)
            for (i = 0; i < 9; i++) M[i] += q[q0 + b] * w->T[9 * (q0 + b) + i];
        for (i = 0; i < 3; i++) v += c[3 * d + i] * c[3 * d + i];
        v *= m->mass[d];
        for (b = 0; b < r; b++) v += 2.0 * m->a[q0 + b] * q[q0 + b] + q[q0 + b] * q[q0 + b];
        E += 0.5 * inertia * v - sum9(Rd, M);
        for (i = 0; i < 3; i++) E -= w->t[3 * d + i] * c[3 * d + i];
        E += domain_quartic(m, (int)d, q + q0, g ? w->gq : NULL, w->Hq, w->quartic);
        if (!g) continue;
        turned(Rd, GR);
        for (i = 0; i < 3; i++) {
            g[o + i] = inertia * m->mass[d] * c[3 * d + i] - w->t[3 * d + i];
            g[o + 3 + i] = -sum9(GR[i], M);
            H[(o + i) * Z + o + i] = inertia * m->mass[d];
            for (k = 0; k < 3; k++) {
                double v2 = 0.0;
                int e;
                cross_with((int)i, GR[k], a9);
                cross_with((int)k, GR[i], b9);
                for (e = 0; e < 9; e++) v2 += 0.5 * (a9[e] + b9[e]) * M[e];
                H[(o + 3 + i) * Z + o + 3 + k] = -v2;
            }
        }
        for (b = 0; b < r; b++) {
            const double *Tb = w->T + 9 * (q0 + b);
            long cc;
            g[o + 6 + b] = inertia * (m->a[q0 + b] + q[q0 + b]) - sum9(Rd, Tb) + w->gq[b];
            H[(o + 6 + b) * Z + o + 6 + b] = inertia;
            for (k = 0; k < 3; k++) {
                double v3 = -sum9(GR[k], Tb);
                H[(o + 3 + k) * Z + o + 6 + b] = v3;
                H[(o + 6 + b) * Z + o + 3 + k] = v3;
            }
            for (cc = 0; cc < r; cc++) H[(o + 6 + b) * Z + o + 6 + cc] += w->Hq[b * r + cc];
        }
    }
    framed_positions(m, st, m->joint_nodes, m->nodes, w->x);
    return E + joint_terms(m, st, w, g, H);
}

/* The derivatives in the tree's unknowns: g (Z,) and H (Z, Z) from the free-centre ones
 * (framed_energy), and N (3 D, Z), the centres' moves per unit move of the tree's unknowns
 * less the identity. HN, CN: scratch (Z, Z) and (3 D, Z). */
static double framed_derivatives(const af_framed *m, const double *st, framed_scratch *w,
                                 double inertia, double *g, double *H, double *N, double *HN,
                                 double *CN, double *gc_all) {
    long Z = m->Z, D = m->D, C = 3 * D, p, i, j, a, b;
    const double *R = st + 3 * D;
    double E = framed_energy(m, st, w, inertia, g, H);
    for (i = 0; i < C * Z; i++) N[i] = 0.0;
    for (p = 0; p < m->links; p++) {
        int f = m->chain[2 * p], d = m->chain[2 * p + 1];
        const double *arm = m->arms + 3 * p, *Rf = R + 9 * f;
        double wv[3], gc[3], gw;
        long zc = m->z0[f], zt = m->z0[f] + 3;
        for (a = 0; a < 3; a++) wv[a] = Rf[3 * a] * arm[0] + Rf[3 * a + 1] * arm[1] + Rf[3 * a + 2] * arm[2];
        if (f != d) for (a = 0; a < 3; a++) N[(3 * d + a) * Z + zc + a] += 1.0;
        N[(3 * d) * Z + zt + 1] += wv[2];
        N[(3 * d) * Z + zt + 2] -= wv[1];
        N[(3 * d + 1) * Z + zt] -= wv[2];
        N[(3 * d + 1) * Z + zt + 2] += wv[0];
        N[(3 * d + 2) * Z + zt] += wv[1];
        N[(3 * d + 2) * Z + zt + 1] -= wv[0];
        for (a = 0; a < 3; a++) gc[a] = g[m->z0[d] + a];
        gw = gc[0] * wv[0] + gc[1] * wv[1] + gc[2] * wv[2];
        for (a = 0; a < 3; a++) {
            for (b = 0; b < 3; b++) H[(zt + a) * Z + zt + b] += 0.5 * (gc[a] * wv[b] + gc[b] * wv[a]);
            H[(zt + a) * Z + zt + a] -= gw;
        }
    }
    /* H + HN + HN^T + N^T H[C, C] N, HN = H[:, C] N; g + N^T g[C] */
    for (i = 0; i < Z * Z; i++) HN[i] = 0.0;
    for (i = 0; i < C * Z; i++) CN[i] = 0.0;
    for (i = 0; i < Z; i++)
        for (a = 0; a < C; a++) {
            double h = H[i * Z + m->z0[a / 3] + a % 3];
            if (h == 0.0) continue;
            for (j = 0; j < Z; j++) HN[i * Z + j] += h * N[a * Z + j];
        }
    for (a = 0; a < C; a++)
        for (b = 0; b < C; b++) {
            double h = H[(m->z0[a / 3] + a % 3) * Z + m->z0[b / 3] + b % 3];
            if (h == 0.0) continue;
            for (j = 0; j < Z; j++) CN[a * Z + j] += h * N[b * Z + j];
        }
    for (i = 0; i < Z; i++)
        for (j = 0; j < Z; j++) H[i * Z + j] += HN[i * Z + j] + HN[j * Z + i];
    for (a = 0; a < C; a++)
        for (i = 0; i < Z; i++) {
            double n = N[a * Z + i];
            if (n == 0.0) continue;
            for (j = 0; j < Z; j++) H[i * Z + j] += n * CN[a * Z + j];
        }
    for (a = 0; a < C; a++) gc_all[a] = g[m->z0[a / 3] + a % 3];
    for (a = 0; a < C; a++)
        for (i = 0; i < Z; i++) g[i] += N[a * Z + i] * gc_all[a];
    return E;
}

/* the largest node move of dz (the centres' free moves dz + N dz), m */
static double framed_bound(const af_framed *m, const double *dz, const double *N) {
    long d, a, j, b, Z = m->Z;
    double worst = 0.0;
    for (d = 0; d < m->D; d++) {
        long o = m->z0[d];
        double c2 = 0.0, t2 = 0.0, q2 = 0.0, v;
        for (a = 0; a < 3; a++) {
            v = dz[o + a];
            for (j = 0; j < Z; j++) v += N[(3 * d + a) * Z + j] * dz[j];
            c2 += v * v;
            t2 += dz[o + 3 + a] * dz[o + 3 + a];
        }
        for (b = 0; b < m->r[d]; b++) q2 += dz[o + 6 + b] * dz[o + 6 + b];
        v = sqrt(c2) + sqrt(t2) * m->radius[d] + sqrt(q2) * m->reach[d];
        if (v > worst) worst = v;
    }
    return worst;
}

/* exp([theta]_x) (9) by Rodrigues' formula */
static void rotation_of(double t0, double t1, double t2, double *out) {
    double angle = sqrt(t0 * t0 + t1 * t1 + t2 * t2);
    double first = angle > 0 ? sin(angle) / angle : 1.0;
    double half = angle > 0 ? sin(0.5 * angle) / (0.5 * angle) : 1.0;
    double K[9] = {0, -t2, t1, t2, 0, -t0, -t1, t0, 0};
    int i, j, l;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            double KK = 0.0;
            for (l = 0; l < 3; l++) KK += K[3 * i + l] * K[3 * l + j];
            out[3 * i + j] = (i == j ? 1.0 : 0.0) + first * K[3 * i + j] + 0.5 * half * half * KK;
        }
}

static void mul3(const double *A, const double *B, double *out) {
    int i, j;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++)
            out[3 * i + j] = A[3 * i] * B[j] + A[3 * i + 1] * B[3 + j] + A[3 * i + 2] * B[6 + j];
}

/* to_moves: each domain's own move t (3 D) of centres c; else the centres c of moves t; the
 * roots hang from base (12) */
static void framed_tree(const af_framed *m, const double *R, const double *base, double *c,
                        double *t, int to_moves) {
    long k, i, j;
    for (k = 0; k < m->D; k++) {
        int e = m->order[k], p = m->parent[e];
        for (i = 0; i < 3; i++) {
            double v = 0.0;
            for (j = 0; j < 3; j++) v += R[9 * e + 3 * i + j] * m->arm_own[3 * e + j];
            if (p < 0) {
                v += base[9 + i];
                for (j = 0; j < 3; j++) v += base[3 * i + j] * m->arm_parent[3 * e + j];
            } else {
                v += c[3 * p + i];
                for (j = 0; j < 3; j++) v += R[9 * p + 3 * i + j] * m->arm_parent[3 * e + j];
            }
            if (to_moves) t[3 * e + i] = c[3 * e + i] - v;
            else c[3 * e + i] = v + t[3 * e + i];
        }
    }
}

/* out = st moved by alpha dz (turns by exp, own moves added, centres carried, q added);
 * t: (3 D) scratch */
static void framed_retract(const af_framed *m, const double *st, const double *dz, double alpha,
                           double *out, double *t) {
    long d, a, b, D = m->D;
    double turn[9];
    framed_tree(m, st + 3 * D, BASE(m, st), (double *)st, t, 1);
    for (b = 0; b < m->Q + 12; b++) out[12 * D + b] = st[12 * D + b];
    for (d = 0; d < D; d++) {
        long o = m->z0[d];
        rotation_of(alpha * dz[o + 3], alpha * dz[o + 4], alpha * dz[o + 5], turn);
        mul3(turn, st + 3 * D + 9 * d, out + 3 * D + 9 * d);
        for (a = 0; a < 3; a++) t[3 * d + a] += alpha * dz[o + a];
        for (b = 0; b < m->r[d]; b++) out[12 * D + m->q0[d] + b] += alpha * dz[o + 6 + b];
    }
    framed_tree(m, out + 3 * D, BASE(m, out), out, t, 0);
}

/* each 3 x 3 block of R (D of them) replaced by its nearest rotation, by Newton's iteration
 * X <- (X + X^-T) / 2 to round-off */
static void nearest_rotations(double *R, long D) {
    long d, it, k;
    for (d = 0; d < D; d++) {
        double *X = R + 9 * d;
        for (it = 0; it < 20; it++) {
            double a = X[0], b = X[1], c = X[2], e = X[3], f = X[4], g = X[5], h = X[6],
                   i = X[7], j = X[8], change = 0.0;
            double det = a * (f * j - g * i) - b * (e * j - g * h) + c * (e * i - f * h);
            double inv[9] = {(f * j - g * i) / det, -(e * j - g * h) / det, (e * i - f * h) / det,
                             -(b * j - c * i) / det, (a * j - c * h) / det, -(a * i - b * h) / det,
                             (b * g - c * f) / det, -(a * g - c * e) / det, (a * f - b * e) / det};
            for (k = 0; k < 9; k++) {
                double v = 0.5 * (X[k] + inv[k]);
                if (fabs(v - X[k]) > change) change = fabs(v - X[k]);
                X[k] = v;
            }
            if (change <= 1e-16) break;
        }
    }
}

/* Newton's start, the held nodes at base (12): each frame turned on by its last turn, its own
 * move and q carried on */
static void framed_extrapolated(const af_framed *m, const double *now, const double *before,
                                const double *base, double *out, double *t, double *t2) {
    long d, i, j, D = m->D;
    double bt[9], turn[9];
    for (d = 0; d < D; d++) {
        const double *Rn = now + 3 * D + 9 * d, *Rb = before + 3 * D + 9 * d;
        for (i = 0; i < 3; i++) for (j = 0; j < 3; j++) bt[3 * i + j] = Rb[3 * j + i];
        mul3(Rn, bt, turn);
        mul3(turn, Rn, out + 3 * D + 9 * d);
    }
    nearest_rotations(out + 3 * D, D);
    memcpy(BASE(m, out), base, 12 * sizeof(double));
    framed_tree(m, now + 3 * D, BASE(m, now), (double *)now, t, 1);
    framed_tree(m, before + 3 * D, BASE(m, before), (double *)before, t2, 1);
    for (i = 0; i < 3 * D; i++) t[i] = 2.0 * t[i] - t2[i];
    framed_tree(m, out + 3 * D, base, out, t, 0);
    for (i = 0; i < m->Q; i++) out[12 * D + i] = 2.0 * now[12 * D + i] - before[12 * D + i];
}

/* base: 12 doubles, a rotation (row-major) and a translation: a rigid motion to 1e-9 */
static int rigid(const double *base) {
    int i, j, k;
    for (i = 0; i < 12; i++) if (!isfinite(base[i])) return 0;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            double s = 0.0;
            for (k = 0; k < 3; k++) s += base[3 * i + k] * base[3 * j + k];
            if (fabs(s - (i == j ? 1.0 : 0.0)) > 1e-9) return 0;
        }
    return base[0] * (base[4] * base[8] - base[5] * base[7])
           - base[1] * (base[3] * base[8] - base[5] * base[6])
           + base[2] * (base[3] * base[7] - base[4] * base[6]) > 0.0;
}

int af_framed_step(af_framed *m, const double *now, const double *before, double *next,
                   const double *force, const double *base, double dt, int max_iter) {
    long Z = m->Z, D = m->D, S = 12 * D + m->Q + 12, i, it;
    double *cursor = m->work, inertia, tolerance, bound = INFINITY;
    framed_scratch w;
    double *g, *H, *N, *HN, *CN, *L, *V, *B, *lam, *t1, *dz, *gc, *state, *trial, *t, *t2;
#define TAKE(count) (cursor += (count), cursor - (count))
    if (!(dt > 0.0) || max_iter < 1) return AF_BAD_INPUT;
    if (!base) base = BASE(m, now);
    if (!rigid(base)) return AF_BAD_INPUT;
    if (force) for (i = 0; i < 3L * m->n; i++) if (!isfinite(force[i])) return AF_BAD_INPUT;
    for (i = 0; i < S; i++) if (!isfinite(now[i]) || !isfinite(before[i])) return AF_BAD_INPUT;
    w.T0 = TAKE(9 * D); w.T = TAKE(9 * m->Q); w.t = TAKE(3 * D);
    w.x = TAKE(3 * m->nodes); w.grad = TAKE(3 * m->nodes); w.blocks = TAKE(9 * m->pairs);
    w.Jn = TAKE(3L * m->nodes * (6 + m->rmax)); w.K = TAKE(3 * Z);
    w.gq = TAKE(m->rmax); w.Hq = TAKE(m->rmax * m->rmax); w.Hs = TAKE(Z * Z);
    w.quartic = TAKE((m->rmax + 2) * (m->rmax + 2) * (m->rmax + 2) / 6 * 2 + 2 * m->rmax * m->rmax);
    g = TAKE(Z); H = TAKE(Z * Z); N = TAKE(3 * D * Z); HN = TAKE(Z * Z); CN = TAKE(3 * D * Z);
    L = TAKE(Z * Z); V = TAKE(Z * Z); B = TAKE(Z * Z); lam = TAKE(Z); t1 = TAKE(Z);
    dz = TAKE(Z); gc = TAKE(3 * D); state = TAKE(S); trial = TAKE(S); t = TAKE(3 * D);
    t2 = TAKE(3 * D);
#undef TAKE
    inertia = 1.0 / (dt * dt);
    framed_targets(m, now, before, force, inertia, w.T0, w.T, w.t);
    framed_extrapolated(m, now, before, base, state, t, t2);
    tolerance = STEP_TOLERANCE * m->size;
    for (it = 1; it <= max_iter; it++) {
        double E = framed_derivatives(m, state, &w, inertia, g, H, N, HN, CN, gc), last, alpha,
               slope = 0.0;
        if (!isfinite(E)) return AF_NOT_CONVERGED;
        for (i = 0; i < Z; i++) if (!isfinite(g[i])) return AF_NOT_CONVERGED;
        newton_direction(H, g, dz, L, V, lam, B, t1, Z, MIRROR_FLOOR, 1);
        last = bound;
        bound = framed_bound(m, dz, N);
        if (bound <= tolerance || (bound < last && last < INFINITY
                                   && bound * bound / last <= tolerance)) {
            framed_retract(m, state, dz, 1.0, next, t);
            nearest_rotations(next + 3 * D, D);
            m->iterations = (int)it;
            return AF_OK;
        }
        for (i = 0; i < Z; i++) slope += g[i] * dz[i];
        for (alpha = 1.0;; alpha *= 0.5) {
            if (alpha < 1.0 && alpha * bound <= tolerance) {
                if (bound <= 1e3 * tolerance) {  /* round-off: no decrease resolved */
                    memcpy(next, state, (size_t)S * sizeof(double));
                    m->iterations = (int)it;
                    return AF_OK;
                }
                return AF_NOT_CONVERGED;
            }
            framed_retract(m, state, dz, alpha, trial, t);
            if (framed_energy(m, trial, &w, inertia, NULL, NULL) <= E + ARMIJO * alpha * slope)
                break;
        }
        memcpy(state, trial, (size_t)S * sizeof(double));
    }
    m->iterations = (int)max_iter;
    return AF_NOT_CONVERGED;
}
