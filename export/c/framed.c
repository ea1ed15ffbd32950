/* The framed model (`python -m export reduced --framed`): export/framed_runtime.py's
 * FramedSimulator, the same step in the same order. Domain d's node i sits at
 * R_d (y_i + U_i q_d) + c_d; a step is Newton over each domain's own move t, turn theta and
 * coordinates q, the centres carried along the domains' kinematic tree.
 */

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "af_internal.h"

#define MIRROR_FLOOR 1e-10

struct af_framed {
    int n, D, Q, Z, rmax, joints, points, k, nodes, pairs, links;
    int nf, dk;                /* the model's nodes; model nodes per display vertex (0: none) */
    int *display_nodes;        /* (n, dk): each vertex's model nodes, where a display mesh */
    double *display_weights;   /* (n, dk): their weights */
    const double *x0;          /* the model nodes' rest positions */
    double *physics_rest, *spread; /* x0 where a display mesh's; forces spread on the nodes */
    double size;
    int *labels, *r, *q0, *z0, *b0, *parent, *order, *chain, *poly;
    int *joint_nodes, *joint_labels, *joint_tets, *pair_list, *pair_ptr, *element_pairs;
    const double *rest, *masses;   /* (n, 3) and (n,), the model's */
    double *Y, *U, *centre, *mass, *a, *J, *A, *B, *radius, *reach;
    double *c0, *c1, *C2, *S3, *W4, *arm_parent, *arm_own, *arms;
    double *grads, *weights, *mu, *lam, *kappa, *fiber;
    double *constant;          /* the constant force's moments: T0 (9 D), T (9 Q), t (3 D) */
    double *work;
};

void af_framed_close(af_framed *m) {
    if (!m) return;
    free(m->labels); free(m->r); free(m->q0); free(m->z0); free(m->b0); free(m->parent);
    free(m->order); free(m->chain); free(m->poly); free(m->joint_nodes); free(m->joint_labels);
    free(m->joint_tets); free(m->pair_list); free(m->pair_ptr); free(m->element_pairs);
    free(m->Y); free(m->U); free(m->centre); free(m->mass);
    free(m->a); free(m->J); free(m->A); free(m->B); free(m->radius); free(m->reach);
    free(m->c0); free(m->c1); free(m->C2); free(m->S3); free(m->W4); free(m->arm_parent);
    free(m->arm_own); free(m->arms); free(m->grads); free(m->weights); free(m->mu);
    free(m->lam); free(m->kappa); free(m->fiber); free(m->constant); free(m->work);
    free(m->display_nodes); free(m->display_weights); free(m->spread);
    free(m->physics_rest);
    free(m);
}

static int compare_longs(const void *x, const void *y) {
    long a = *(const long *)x, b = *(const long *)y;
    return (a > b) - (a < b);
}

/* The joints' compact node numbering, their node pairs and each element's pairs. */
static int plan_joints(af_framed *m, const int *tets) {
    long e, a, b, i, total = (long)m->joints * m->k, count = 0, unique = 0;
    long *keys = (long *)malloc((size_t)(total > 0 ? total : 1) * sizeof(long) * (size_t)m->k);
    int *local = (int *)malloc((size_t)m->nf * sizeof(int));
    if (!keys || !local) { free(keys); free(local); return 0; }
    for (i = 0; i < m->nf; i++) local[i] = -1;
    for (e = 0; e < total; e++) local[tets[e]] = 0;
    m->nodes = 0;
    for (i = 0; i < m->nf; i++) if (local[i] == 0) local[i] = m->nodes++;
    m->joint_nodes = (int *)malloc((size_t)m->nodes * sizeof(int) + 1);
    m->joint_labels = (int *)malloc((size_t)m->nodes * sizeof(int) + 1);
    m->joint_tets = (int *)malloc((size_t)total * sizeof(int) + 1);
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
    m->pair_list = (int *)malloc((size_t)(2 * unique) * sizeof(int) + 1);
    m->pair_ptr = (int *)calloc((size_t)m->nodes + 1, sizeof(int));
    m->element_pairs = (int *)malloc((size_t)(count > 0 ? count : 1) * sizeof(int));
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
                long *hit = (long *)bsearch(&key, keys, (size_t)unique, sizeof(long),
                                            compare_longs);
                m->element_pairs[(e * m->k + a) * m->k + b] = (int)(hit - keys);
            }
    free(keys);
    free(local);
    return 1;
}

#define F64(field, name, dims) \
    if (!(m->field = (double *)af_array(f, name, 1, "float64", dims, shape))) goto fail
#define I32(field, name, dims) \
    if (!(m->field = (int *)af_array(f, name, 1, "int32", dims, shape))) goto fail

/* A display mesh's arrays where the file has them (display_nodes, display_weights,
 * physics_rest: each of the n vertices a weighted sum of the model's nf nodes), else the
 * vertices are the model's nodes. 0 with the reason in the file's error where they do not fit. */
static int load_display(af_framed *m, const af_file *f) {
    long shape[4], i;
    m->x0 = m->rest;
    if (!af_has_array(f, "display_nodes", 0)) {
        if (m->nf == m->n) return 1;
        af_say(f->error, f->error_size, "%s: array labels has %d entries for %d vertices, and "
               "no display_nodes maps a display mesh's vertices on them", f->name, m->nf, m->n);
        return 0;
    }
    if (!(m->display_nodes = (int *)af_array(f, "display_nodes", 0, "int32", 2, shape)))
        return 0;
    m->dk = (int)shape[1];
    if (shape[0] != m->n) {
        af_say(f->error, f->error_size, "%s: array display_nodes has %ld rows for %d vertices",
               f->name, shape[0], m->n);
        return 0;
    }
    for (i = 0; i < (long)m->n * m->dk; i++)
        if (m->display_nodes[i] < 0 || m->display_nodes[i] >= m->nf) {
            af_say(f->error, f->error_size, "%s: array display_nodes names node %d, outside the "
                   "model's %d", f->name, m->display_nodes[i], m->nf);
            return 0;
        }
    if (!(m->display_weights = (double *)af_array(f, "display_weights", 0, "float64", 2, shape)))
        return 0;
    if (shape[0] != m->n || shape[1] != m->dk) {
        af_say(f->error, f->error_size, "%s: array display_weights is not shaped as "
               "display_nodes", f->name);
        return 0;
    }
    if (!(m->physics_rest = (double *)af_array(f, "physics_rest", 0, "float64", 2, shape)))
        return 0;
    m->x0 = m->physics_rest;
    if (shape[0] != m->nf || shape[1] != 3) {
        af_say(f->error, f->error_size, "%s: array physics_rest has %ld rows for the model's %d "
               "nodes", f->name, shape[0], m->nf);
        return 0;
    }
    if (!(m->spread = (double *)malloc((size_t)(3L * m->nf) * sizeof(double)))) {
        af_say(f->error, f->error_size, "no memory for a model");
        return 0;
    }
    return 1;
}

/* each domain-indexed array's length against D (or D x rows), naming the first that is off */
static int domain_shape(const af_file *f, const char *name, long got, long expected) {
    if (got == expected) return 1;
    af_say(f->error, f->error_size, "%s: array %s%s has %ld rows, expected %ld (one per domain "
           "or per coordinate)", f->name, name, f->tag, got, expected);
    return 0;
}

af_framed *af_framed_open(const af_file *f, int n, const double *rest, const double *masses) {
    const char *v;
    long shape[4], d, q = 0, z = 0, b = 0, P, width;
    int *tets = NULL;
    af_framed *m = (af_framed *)calloc(1, sizeof *m);
    if (!m) {
        af_say(f->error, f->error_size, "no memory for a model");
        return NULL;
    }
    m->n = n;
    m->rest = rest;
    m->masses = masses;
    v = af_top_value(f->json, "size");
    m->size = v ? strtod(v, NULL) : 0.0;
    if (!(m->size > 0.0) || !isfinite(m->size)) {
        af_say(f->error, f->error_size, "%s: the header's \"size\" (the body's size, m) is "
               "missing or not a positive number", f->name);
        goto fail;
    }
    I32(labels, "labels", 1);
    m->nf = (int)shape[0];
    if (!load_display(m, f)) goto fail;
    I32(r, "r", 1);
    m->D = (int)shape[0];
    F64(Y, "Y", 2);
    if (!domain_shape(f, "Y", shape[0], m->nf)) goto fail;
    F64(U, "U", 3);
    if (!domain_shape(f, "U", shape[0], m->nf)) goto fail;
    m->rmax = (int)shape[2];
    for (d = 0; d < m->nf; d++)
        if (m->labels[d] < -1 || m->labels[d] >= m->D) {
            af_say(f->error, f->error_size, "%s: array labels%s names domain %d of %d", f->name,
                   f->tag, m->labels[d], m->D);
            goto fail;
        }
    for (d = 0; d < m->D; d++)
        if (m->r[d] < 0 || m->r[d] > m->rmax) {
            af_say(f->error, f->error_size, "%s: array r%s gives domain %ld %d coordinates, "
                   "outside 0-%d", f->name, f->tag, d, m->r[d], m->rmax);
            goto fail;
        }
    F64(centre, "centre", 2);
    if (!domain_shape(f, "centre", shape[0], m->D)) goto fail;
    F64(mass, "mass", 1);
    if (!domain_shape(f, "mass", shape[0], m->D)) goto fail;
    F64(a, "a", 1); F64(J, "J", 3);
    if (!domain_shape(f, "J", shape[0], m->D)) goto fail;
    F64(A, "A", 3); F64(B, "B", 3); F64(radius, "radius", 1); F64(reach, "reach", 1);
    F64(c0, "c0", 1);
    if (!domain_shape(f, "c0", shape[0], m->D)) goto fail;
    F64(c1, "c1", 1); F64(C2, "C2", 1); F64(S3, "S3", 1); F64(W4, "W4", 1);
    I32(poly, "poly_offsets", 2);
    if (!domain_shape(f, "poly_offsets", shape[0], m->D)) goto fail;
    I32(parent, "parent", 1); I32(order, "order", 1);
    F64(arm_parent, "arm_parent", 2); F64(arm_own, "arm_own", 2);
    I32(chain, "chain", 2);
    P = shape[0];
    F64(arms, "arms", 2);
    F64(grads, "joint_grads", 4);
    m->joints = (int)shape[0]; m->points = (int)shape[1]; m->k = (int)shape[2];
    F64(weights, "joint_weights", 2); F64(mu, "mu", 1); F64(lam, "lam", 1);
    F64(kappa, "kappa", 1); F64(fiber, "fiber", 2);
    if (!(tets = (int *)af_array(f, "joint_tets", 1, "int32", 2, shape))) goto fail;
    if (shape[0] != m->joints || shape[1] != m->k) {
        af_say(f->error, f->error_size, "%s: array joint_tets%s is not shaped as joint_grads' "
               "elements and nodes", f->name, f->tag);
        goto fail;
    }
    for (d = 0; d < (long)m->joints * m->k; d++)
        if (tets[d] < 0 || tets[d] >= m->nf) {
            af_say(f->error, f->error_size, "%s: array joint_tets%s names node %d, outside the "
                   "model's %d", f->name, f->tag, tets[d], m->nf);
            goto fail;
        }
    if (m->D > 64 || m->k > 16 || m->dk > 16) {
        af_say(f->error, f->error_size, "%s: this runtime steps at most 64 domains and 16 nodes "
               "an element", f->name);
        goto fail;
    }
    m->links = (int)P;
    m->q0 = (int *)malloc((size_t)m->D * sizeof(int) + 1);
    m->z0 = (int *)malloc((size_t)m->D * sizeof(int) + 1);
    m->b0 = (int *)malloc((size_t)m->D * sizeof(int) + 1);
    if (!m->q0 || !m->z0 || !m->b0 || !plan_joints(m, tets)) {
        af_say(f->error, f->error_size, "no memory for a model");
        goto fail;
    }
    for (d = 0; d < m->D; d++) {
        m->q0[d] = (int)q; m->z0[d] = (int)z; m->b0[d] = (int)b;
        q += m->r[d]; z += 6 + m->r[d]; b += (long)m->r[d] * m->r[d];
    }
    m->Q = (int)q; m->Z = (int)z;
    width = 6 + m->rmax;
    {   /* work: the scratch of af_framed_advance (framed_scratch) */
        long Z = m->Z, D = m->D, nodes = m->nodes, rm = m->rmax;
        size_t doubles = (size_t)(7 * Z * Z + 2 * 3 * D * Z + 8 * Z
                                  + 3 * nodes * (2 + 3 * width) + 9 * (long)m->pairs
                                  + 9 * D + 9 * m->Q + 3 * D + 5 * (12 * D + m->Q) + 9 * D
                                  + (rm + 2) * (rm + 2) * (rm + 2) / 6 * 2 + 3 * rm * rm
                                  + 4 * rm + 256);
        m->work = (double *)malloc(doubles * sizeof(double));
        m->constant = (double *)calloc((size_t)(9 * D + 9 * m->Q + 3 * D), sizeof(double));
        if (!m->work || !m->constant) {
            af_say(f->error, f->error_size, "no memory for a model");
            goto fail;
        }
    }
    free(tets);
    return m;
fail:
    free(tets);
    af_framed_close(m);
    return NULL;
}
#undef F64
#undef I32

int af_framed_size(const af_framed *m) { return 12 * m->D + m->Q + 12; }

static void framed_moments(const af_framed *m, const double *force, double *T0, double *T,
                           double *t);

int af_framed_set_force(af_framed *m, const double *force) {
    long i, count = 9L * m->D + 9L * m->Q + 3L * m->D;
    for (i = 0; i < count; i++) m->constant[i] = 0.0;
    if (force)
        framed_moments(m, force, m->constant, m->constant + 9L * m->D,
                       m->constant + 9L * m->D + 9L * m->Q);
    return AF_OK;
}

/* the base of a state: [R_g (9, row-major) | c_g (3)] after its coordinates */
#define BASE(m, st) ((st) + 12 * (m)->D + (m)->Q)

void af_framed_rest(const af_framed *m, double *state) {
    long d, i;
    for (i = 0; i < 12L * m->D + m->Q + 12; i++) state[i] = 0.0;
    for (d = 0; d < m->D; d++) {
        for (i = 0; i < 3; i++) state[3 * d + i] = m->centre[3 * d + i];
        for (i = 0; i < 3; i++) state[3 * m->D + 9 * d + 4 * i] = 1.0;
    }
    for (i = 0; i < 3; i++) BASE(m, state)[4 * i] = 1.0;
}

void af_framed_carry(const af_framed *m, double *state, const double *base) {
    double *c = state, *R = state + 3 * m->D, *g = BASE(m, state), t[9];
    long d, a, b, k;
    for (d = 0; d < m->D + 1; d++) {   /* every frame, then the base */
        double *Rd = d < m->D ? R + 9 * d : g, *cd = d < m->D ? c + 3 * d : g + 9, y[3];
        for (a = 0; a < 3; a++)
            for (b = 0; b < 3; b++) {
                t[3 * a + b] = 0.0;
                for (k = 0; k < 3; k++) t[3 * a + b] += base[3 * a + k] * Rd[3 * k + b];
            }
        memcpy(Rd, t, sizeof t);
        for (a = 0; a < 3; a++)
            y[a] = base[3 * a] * cd[0] + base[3 * a + 1] * cd[1] + base[3 * a + 2] * cd[2]
                   + base[9 + a];
        memcpy(cd, y, sizeof y);
    }
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

void af_framed_place(const af_framed *m, const double *state, double *x) {
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
    for (a = 0; a < T; a++) A[a] = af_dot(W4 + a * r, q, r);
    af_contract(A, q, X, r);
    for (a = 0; a < r * r; a++) Y[a] = af_dot(S3 + a * r, q, r);
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

int af_rigid(const double *base) {
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

int af_framed_advance(af_framed *m, const double *now, const double *before, double *next,
                      const double *force, const double *base, double dt, double step_share,
                      int max_iter, char *error, size_t error_size) {
    long Z = m->Z, D = m->D, S = 12 * D + m->Q + 12, i, it;
    double *cursor = m->work, inertia, tolerance, bound = INFINITY;
    framed_scratch w;
    double *g, *H, *N, *HN, *CN, *L, *V, *B, *lam, *t1, *dz, *gc, *state, *trial, *t, *t2;
#define TAKE(count) (cursor += (count), cursor - (count))
    if (!base) base = BASE(m, now);
    if (!af_rigid(base)) {
        af_say(error, error_size, "base: not a rigid motion (its first 9 numbers must be a "
               "rotation, row-major, to 1e-9; then a translation)");
        return AF_BAD_INPUT;
    }
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
    tolerance = step_share * m->size;
    for (it = 1; it <= max_iter; it++) {
        double E = framed_derivatives(m, state, &w, inertia, g, H, N, HN, CN, gc), last, alpha,
               slope = 0.0;
        for (i = 0; i < Z && isfinite(E); i++) if (!isfinite(g[i])) E = NAN;
        if (!isfinite(E)) {
            af_say(error, error_size, "step: the energy or its gradient is not finite at "
                   "iteration %ld", it);
            return AF_NOT_CONVERGED;
        }
        af_newton_direction(H, g, dz, L, V, lam, B, t1, Z, MIRROR_FLOOR, 1);
        last = bound;
        bound = framed_bound(m, dz, N);
        if (bound <= tolerance || (bound < last && last < INFINITY
                                   && bound * bound / last <= tolerance)) {
            framed_retract(m, state, dz, 1.0, next, t);
            nearest_rotations(next + 3 * D, D);
            return (int)it;
        }
        for (i = 0; i < Z; i++) slope += g[i] * dz[i];
        for (alpha = 1.0;; alpha *= 0.5) {
            if (alpha < 1.0 && alpha * bound <= tolerance) {
                if (bound <= 1e3 * tolerance) {  /* round-off: no decrease resolved */
                    memcpy(next, state, (size_t)S * sizeof(double));
                    return (int)it;
                }
                af_say(error, error_size, "step: the line search found no decrease at iteration "
                       "%ld (the step's largest move %.3g m)", it, bound);
                return AF_NOT_CONVERGED;
            }
            framed_retract(m, state, dz, alpha, trial, t);
            if (framed_energy(m, trial, &w, inertia, NULL, NULL) <= E + AF_ARMIJO * alpha * slope)
                break;
        }
        memcpy(state, trial, (size_t)S * sizeof(double));
    }
    af_say(error, error_size, "step: Newton stopped after %d iterations, its last move %.3g m "
           "against a tolerance of %.3g m", max_iter, bound, tolerance);
    return AF_NOT_CONVERGED;
}
