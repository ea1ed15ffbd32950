/* A reduced model's contact with rigid obstacles, as export/runtime.py's Contact steps it
 * (anisofem.physics.contact's method): the IPC barrier kappa A b(d), b(d) = -(d - dhat)^2
 * ln(d / dhat), at the surface nodes x_s = rest + U q; friction lagged at a step's start, mu
 * lambda f0(|T (x - x_n)|) with f0 smoothed below eps = smoothing dt; the largest share of a
 * step that keeps every node at KEEP of its distance from every obstacle (Newton on the convex
 * distance along the move, which never passes its first root). Obstacles: a plane, and a
 * sphere, box or capsule as a convex core grown by a radius; af_contact_move sets where one
 * is to be, reached as far as the body lets it at the next step's start.
 *
 * A free obstacle (af_contact_motion: a mass, an inertia about a center, its velocity and the
 * acceleration all else gives it) moves with the body: a step's unknowns are z = (q, then per
 * free obstacle sqrt(m) y and, where it turns, s delta), y its move over the step, delta a
 * turn about its center after the turn S it has made so far in the solve (s^2 its inertia's
 * mean principal value: mass-weighted like the basis's coordinates). Each accepted Newton step
 * folds delta into S (af_contact_settle), so derivatives are taken at delta = 0, exactly. A
 * node x is seen in the obstacle's frame at the step's start: x' = center + S^T exp(-delta)
 * (x - center - y). Their inertia m |y - y_hat|^2 / (2 dt^2) and (theta - theta_hat)^T I
 * (theta - theta_hat) / (2 dt^2), theta = log(exp(delta) S), are terms here. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "af_internal.h"

#define KEEP 0.1
#define TOUCH_ITERATIONS 60
#define TOUCH_TOLERANCE 1e-3
#define GEOMETRY 15
#define NOISE 1e-12      /* the share of the energy below which two values are round-off */
#define UNKNOWNS 6       /* a free obstacle's most unknowns: its move and its turn */

typedef struct {
    int node, obstacle;          /* the surface node (row of contact_rest), the obstacle */
    double weight, T[9], start[3];
} lag_t;

/* An obstacle's motion: free (a mass), or moved only by af_contact_move. */
typedef struct {
    double mass;                 /* kg; 0: moved only by af_contact_move */
    double inertia[9];           /* about its center, kg m^2; zeros: it does not turn */
    double scale;                /* sqrt of inertia's trace / 3: its turn's unknowns' weight */
    double center[3];            /* the point it turns about, m */
    double offset[3];            /* the center from its position when last set, m */
    int fresh;                   /* whether center is to be set from offset */
    double velocity[6];          /* its center's, m/s, then its spin, rad/s */
    double push[6];              /* the acceleration all else gives it, m/s^2 and rad/s^2 */
    double hat[6];               /* dt v + dt^2 a for this step */
    double turned[9];            /* its turn from how the file has it (row-major) */
    double spun[9];              /* its turn so far in this step's solve */
    double view[9], moved[3];    /* exp(th) S and y at the point prepare was last given */
    double target[9];            /* the turn to give it at the next step's start */
    int turning;                 /* whether target is set */
    int slot;                    /* its first unknown in z this step, or -1 */
} body_t;

struct af_contact {
    long k, r;
    int count;                   /* obstacles */
    double *rest, *U, *area;     /* (k, 3), (k, 3, r), (k,) */
    double dhat, kappa, mu, smoothing, eps;
    unsigned char *kinds;
    double *geometry, *friction; /* (count, 15), (count,) */
    double *target;              /* (count, 3) where each is to be */
    double *shift;               /* (count, 3) its move at this step's start */
    unsigned char *moving;       /* (count,) whether it has a target */
    body_t *bodies;              /* (count,) */
    lag_t *lags;
    long lagged;
    char *names;                 /* the obstacles' names, each ended by a NUL */
    long extra;                  /* this solve's unknowns beside q */
    double inertia;              /* this step's 1 / dt^2 */
    double *wrench;              /* (count, 6) force on each, N, and its moment about its
                                    center, N m, at the last step's end */
    double *xs, *gs, *ds;        /* scratch (k, 3) each */
    double *blocks, *pulls;      /* scratch (count, 9), (count, 3): a node's Hessian and
                                    gradient in x' from each obstacle */
    double *g, *H, *qt;          /* the terms' gradient (n), Hessian (n, n); a point (n),
                                    n = r + UNKNOWNS count at most */
};

void af_contact_close(af_contact *c) {
    if (!c) return;
    free(c->rest); free(c->U); free(c->area); free(c->kinds); free(c->geometry);
    free(c->friction); free(c->target); free(c->shift); free(c->moving); free(c->lags);
    free(c->xs); free(c->bodies); free(c->wrench); free(c->blocks); free(c->pulls);
    free(c->gs); free(c->ds); free(c->names); free(c->g); free(c->H); free(c->qt);
    free(c);
}

af_contact *af_contact_open(const af_file *f, int r, int *failed) {
    long shape[4], k;
    double *constants = NULL;
    int i, count = 0;
    const char *v;
    af_contact *c;
    *failed = 0;
    if (!af_has_array(f, "contact_rest", 0)) return NULL;
    *failed = 1;
    if (!(c = (af_contact *)calloc(1, sizeof *c))) {
        af_say(f->error, f->error_size, "no memory for a model's contact");
        return NULL;
    }
    if (!(v = af_top_value(f->json, "obstacles")) || !(c->names = af_string_list(v, &count))) {
        af_say(f->error, f->error_size, "%s: obstacles: expected a list of names", f->name);
        goto fail;
    }
    c->r = r;
    c->count = count;
    if (!(c->rest = (double *)af_array(f, "contact_rest", 0, "float64", 2, shape))) goto fail;
    k = c->k = shape[0];
    if (shape[1] != 3) goto shape;
    if (!(c->U = (double *)af_array(f, "contact_basis", 0, "float64", 3, shape))) goto fail;
    if (shape[0] != k || shape[1] != 3 || shape[2] != r) goto shape;
    if (!(c->area = (double *)af_array(f, "contact_area", 0, "float64", 1, shape))) goto fail;
    if (shape[0] != k) goto shape;
    if (!(constants = (double *)af_array(f, "contact_constants", 0, "float64", 1, shape)))
        goto fail;
    if (shape[0] != 4) goto shape;
    c->dhat = constants[0];
    c->kappa = constants[1];
    c->mu = constants[2];
    c->smoothing = constants[3];
    free(constants);
    constants = NULL;
    if (!(c->kinds = (unsigned char *)af_array(f, "obstacle_kinds", 0, "uint8", 1, shape)))
        goto fail;
    if (shape[0] != count) goto shape;
    for (i = 0; i < count; i++)
        if (c->kinds[i] > AF_CAPSULE) {
            af_say(f->error, f->error_size, "%s: array obstacle_kinds: obstacle %d has kind %d, "
                   "expected 0 to 3", f->name, i, c->kinds[i]);
            goto fail;
        }
    if (!(c->geometry = (double *)af_array(f, "obstacle_geometry", 0, "float64", 2, shape)))
        goto fail;
    if (shape[0] != count || shape[1] != GEOMETRY) goto shape;
    if (!(c->friction = (double *)af_array(f, "obstacle_friction", 0, "float64", 1, shape)))
        goto fail;
    if (shape[0] != count) goto shape;
    c->target = (double *)calloc((size_t)count * 3 + 1, sizeof(double));
    c->shift = (double *)calloc((size_t)count * 3 + 1, sizeof(double));
    c->moving = (unsigned char *)calloc((size_t)count + 1, 1);
    c->lags = (lag_t *)malloc(((size_t)k * (size_t)count + 1) * sizeof(lag_t));
    c->xs = (double *)malloc((size_t)k * 3 * sizeof(double) + 1);
    c->gs = (double *)malloc((size_t)k * 3 * sizeof(double) + 1);
    c->ds = (double *)malloc((size_t)k * 3 * sizeof(double) + 1);
    {
        size_t n = (size_t)r + UNKNOWNS * (size_t)count;
        c->g = (double *)malloc((n + 1) * sizeof(double));
        c->H = (double *)malloc((n * n + 1) * sizeof(double));
        c->qt = (double *)malloc((n + 1) * sizeof(double));
    }
    c->bodies = (body_t *)calloc((size_t)count + 1, sizeof(body_t));
    c->blocks = (double *)calloc((size_t)count * 9 + 1, sizeof(double));
    c->pulls = (double *)calloc((size_t)count * 3 + 1, sizeof(double));
    c->wrench = (double *)calloc((size_t)count * 6 + 1, sizeof(double));
    for (i = 0; c->bodies && i < count; i++) {
        c->bodies[i].slot = -1;
        c->bodies[i].turned[0] = c->bodies[i].turned[4] = c->bodies[i].turned[8] = 1.0;
        memcpy(c->bodies[i].center, c->geometry + i * GEOMETRY, 3 * sizeof(double));
    }
    if (!c->target || !c->shift || !c->moving || !c->lags || !c->xs || !c->gs || !c->ds ||
        !c->g || !c->H || !c->qt || !c->bodies || !c->blocks || !c->pulls || !c->wrench) {
        af_say(f->error, f->error_size, "no memory for a model's contact");
        goto fail;
    }
    *failed = 0;
    return c;
shape:
    af_say(f->error, f->error_size, "%s: the contact arrays do not fit: contact_rest (k, 3), "
           "contact_basis (k, 3, r = %d), contact_area (k,), contact_constants (4,), and "
           "obstacle_kinds (o,), obstacle_geometry (o, 15), obstacle_friction (o,) for the "
           "header's %d obstacles", f->name, r, count);
fail:
    free(constants);
    af_contact_close(c);
    return NULL;
}

int af_contact_count(const af_contact *c) { return c ? c->count : 0; }

const char *af_contact_name(const af_contact *c, int i) {
    const char *p = c->names;
    while (i-- > 0) p += strlen(p) + 1;
    return p;
}

/* The reference point of obstacle i: a plane's point, a sphere's or box's center, a capsule's
 * end a (the first three numbers of its geometry). */
void af_contact_position(const af_contact *c, int i, double *position) {
    memcpy(position, c->geometry + i * GEOMETRY, 3 * sizeof(double));
}

int af_contact_shape(const af_contact *c, int i, double *geometry) {
    memcpy(geometry, c->geometry + i * GEOMETRY, GEOMETRY * sizeof(double));
    return c->kinds[i];
}

void af_contact_move(af_contact *c, int i, const double *position) {
    memcpy(c->target + 3 * i, position, 3 * sizeof(double));
    c->moving[i] = 1;
}

void af_contact_turn(af_contact *c, int i, const double *rotation) {
    memcpy(c->bodies[i].target, rotation, 9 * sizeof(double));
    c->bodies[i].turning = 1;
}

void af_contact_motion(af_contact *c, int i, double mass, const double *inertia,
                       const double *offset, const double *velocity,
                       const double *acceleration) {
    body_t *b = c->bodies + i;
    int a;
    b->mass = mass;
    b->scale = 0.0;
    for (a = 0; a < 9; a++) b->inertia[a] = inertia ? inertia[a] : 0.0;
    if (inertia) b->scale = sqrt((inertia[0] + inertia[4] + inertia[8]) / 3.0);
    for (a = 0; a < 3; a++) b->offset[a] = offset ? offset[a] : 0.0;
    b->fresh = 1;
    memcpy(b->velocity, velocity, 6 * sizeof(double));
    memcpy(b->push, acceleration, 6 * sizeof(double));
}

const double *af_contact_wrench(const af_contact *c, int i) { return c->wrench + 6 * i; }

long af_contact_unknowns(const af_contact *c) { return c ? c->extra : 0; }

/* Whether free obstacle b's turn is among this step's unknowns. */
static int turns(const body_t *b) { return b->scale > 0.0; }

/* Whether obstacle o is free in this step (its move among the unknowns). */
static int is_free(const af_contact *c, int o) { return c->bodies[o].slot >= 0 && c->extra; }

int af_contact_turning(const af_contact *c) {
    int o;
    for (o = 0; c && o < c->count; o++)
        if (is_free(c, o) && turns(c->bodies + o)) return 1;
    return 0;
}

void af_contact_guess(const af_contact *c, double *y) {
    double dt = 1.0 / sqrt(c->inertia);
    int o, a;
    for (o = 0; o < c->count; o++) {
        const body_t *b = c->bodies + o;
        if (b->slot < 0) continue;
        for (a = 0; a < 3; a++) {
            y[b->slot - c->r + a] = dt * b->velocity[a] * sqrt(b->mass);
            if (turns(b)) y[b->slot - c->r + 3 + a] = dt * b->velocity[3 + a] * b->scale;
        }
    }
}

/* d, normal n (3) and, where H is not NULL, the Hessian of d (9) at x from obstacle o. */
static double distance(const af_contact *c, int o, const double *x, double *n, double *H) {
    const double *G = c->geometry + o * GEOMETRY;
    double p[3], r[3], J[9] = {0}, delta, d, radius = 0.0;
    int a, b, inside = 0;
    if (c->kinds[o] == AF_PLANE) {
        d = 0.0;
        for (a = 0; a < 3; a++) {
            d += (x[a] - G[a]) * G[3 + a];
            n[a] = G[3 + a];
        }
        if (H) memset(H, 0, 9 * sizeof(double));
        return d;
    }
    if (c->kinds[o] == AF_SPHERE) {
        memcpy(p, G, sizeof p);
        radius = G[3];
    } else if (c->kinds[o] == AF_CAPSULE) {
        double axis[3], length = 0.0, t = 0.0, s;
        for (a = 0; a < 3; a++) {
            axis[a] = G[3 + a] - G[a];
            length += axis[a] * axis[a];
        }
        length = sqrt(length);
        for (a = 0; a < 3; a++) {
            axis[a] /= length;
            t += (x[a] - G[a]) * axis[a];
        }
        s = t < 0.0 ? 0.0 : t > length ? length : t;
        for (a = 0; a < 3; a++) p[a] = G[a] + s * axis[a];
        if (t > 0.0 && t < length)
            for (a = 0; a < 3; a++)
                for (b = 0; b < 3; b++) J[3 * a + b] = axis[a] * axis[b];
        radius = G[6];
    } else {                          /* a box: center G[0:3], half G[3:6], rotation G[6:15] */
        const double *R = G + 6;
        double local[3], clipped[3];
        int within[3];
        for (b = 0; b < 3; b++) {
            local[b] = 0.0;
            for (a = 0; a < 3; a++) local[b] += (x[a] - G[a]) * R[3 * a + b];
            within[b] = fabs(local[b]) < G[3 + b];
            clipped[b] = local[b] < -G[3 + b] ? -G[3 + b] : local[b] > G[3 + b] ? G[3 + b]
                                                                                  : local[b];
        }
        for (a = 0; a < 3; a++) {
            p[a] = G[a];
            for (b = 0; b < 3; b++) p[a] += clipped[b] * R[3 * a + b];
        }
        for (a = 0; a < 3; a++)
            for (b = 0; b < 3; b++) {
                int e;
                for (e = 0; e < 3; e++) J[3 * a + b] += R[3 * a + e] * within[e] * R[3 * b + e];
            }
        if (within[0] && within[1] && within[2]) {   /* inside: minus the depth to a face */
            int best = 0;
            double depth[3];
            for (b = 0; b < 3; b++) {
                depth[b] = G[3 + b] - fabs(local[b]);
                if (depth[b] < depth[best]) best = b;
            }
            for (a = 0; a < 3; a++) n[a] = R[3 * a + best] * (local[best] > 0 ? 1.0 : -1.0);
            if (H) memset(H, 0, 9 * sizeof(double));
            inside = 1;
            return -depth[best];
        }
    }
    delta = 0.0;
    for (a = 0; a < 3; a++) {
        r[a] = x[a] - p[a];
        delta += r[a] * r[a];
    }
    delta = sqrt(delta);
    for (a = 0; a < 3; a++) n[a] = r[a] / (delta > 0.0 ? delta : 1.0);
    d = delta - radius;
    if (H) {
        for (a = 0; a < 3; a++)
            for (b = 0; b < 3; b++)
                H[3 * a + b] = delta > 0.0 && !inside
                    ? ((a == b) - J[3 * a + b] - n[a] * n[b]) / delta : 0.0;
    }
    return d;
}

static double barrier(double d, double dhat) { return -(d - dhat) * (d - dhat) * log(d / dhat); }

static double barrier_slope(double d, double dhat) {
    return -2.0 * (d - dhat) * log(d / dhat) - (d - dhat) * (d - dhat) / d;
}

static double barrier_curvature(double d, double dhat) {
    return -2.0 * log(d / dhat) - 4.0 * (d - dhat) / d + (d - dhat) * (d - dhat) / (d * d);
}

/* f0'(y) / y of the smoothed friction. */
static double friction_slope(double y, double eps) {
    return y < eps ? -y / (eps * eps) + 2.0 / eps : 1.0 / (y > 1e-300 ? y : 1e-300);
}

/* The surface nodes at z's q into c->xs. */
static void place(af_contact *c, const double *z) {
    long i, a, r = c->r;
    for (i = 0; i < c->k; i++)
        for (a = 0; a < 3; a++)
            c->xs[3 * i + a] = c->rest[3 * i + a] + af_dot(c->U + (3 * i + a) * r, z, r);
}

/* Obstacle o's move y (3, m) and turn th (3, rad, after its turn so far) in z: zeros where it
 * is not free in this step, th zeros where it does not turn. */
static void motion(const af_contact *c, const double *z, int o, double *y, double *th) {
    const body_t *b = c->bodies + o;
    int a, free_ = is_free(c, o);
    for (a = 0; a < 3; a++) {
        y[a] = free_ ? z[b->slot + a] / sqrt(b->mass) : 0.0;
        th[a] = free_ && turns(b) ? z[b->slot + 3 + a] / b->scale : 0.0;
    }
}

/* [w] (row-major): [w] u = w x u. */
static void cross_matrix(const double *w, double *W) {
    W[0] = 0.0; W[1] = -w[2]; W[2] = w[1];
    W[3] = w[2]; W[4] = 0.0; W[5] = -w[0];
    W[6] = -w[1]; W[7] = w[0]; W[8] = 0.0;
}

/* I + p [th] + q [th]^2 (3 x 3, row-major) into M: exp's series and its Jacobians' forms. */
static void series(const double *th, double p, double q, double *M) {
    double K[9];
    int a, b, e;
    cross_matrix(th, K);
    for (a = 0; a < 3; a++)
        for (b = 0; b < 3; b++) {
            double K2 = 0.0;
            for (e = 0; e < 3; e++) K2 += K[3 * a + e] * K[3 * e + b];
            M[3 * a + b] = (a == b ? 1.0 : 0.0) + p * K[3 * a + b] + q * K2;
        }
}

static double norm3(const double *u) { return sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]); }

/* The rotation exp([th]) (row-major) into R. */
static void rotation_of(const double *th, double *R) {
    double angle = norm3(th);
    series(th, angle > 1e-4 ? sin(angle) / angle : 1.0 - angle * angle / 6.0,
           angle > 1e-4 ? (1.0 - cos(angle)) / (angle * angle) : 0.5 - angle * angle / 24.0, R);
}

/* M^T u (3) for a row-major 3 x 3 M, into out (not u). */
static void transposed(const double *M, const double *u, double *out) {
    int a;
    for (a = 0; a < 3; a++) out[a] = M[a] * u[0] + M[3 + a] * u[1] + M[6 + a] * u[2];
}

/* M u (3) for a row-major 3 x 3 M, into out (not u). */
static void times(const double *M, const double *u, double *out) {
    int a;
    for (a = 0; a < 3; a++) out[a] = M[3 * a] * u[0] + M[3 * a + 1] * u[1] + M[3 * a + 2] * u[2];
}

/* M (3 x 3, row-major) made a rotation again: its columns Gram-Schmidt orthonormalized (turns
 * compose without their round-off growing). */
static void orthonormal(double *M) {
    int a, b, e;
    for (b = 0; b < 3; b++) {
        double size = 0.0;
        for (e = 0; e < b; e++) {
            double d = M[e] * M[b] + M[3 + e] * M[3 + b] + M[6 + e] * M[6 + b];
            for (a = 0; a < 3; a++) M[3 * a + b] -= d * M[3 * a + e];
        }
        for (a = 0; a < 3; a++) size += M[3 * a + b] * M[3 * a + b];
        size = sqrt(size);
        for (a = 0; a < 3; a++) M[3 * a + b] /= size;
    }
}

/* A B (3 x 3, row-major) into out; transpose_b: A B^T. out may be neither. */
static void product(const double *A, const double *B, int transpose_b, double *out) {
    int a, b, e;
    for (a = 0; a < 3; a++)
        for (b = 0; b < 3; b++) {
            out[3 * a + b] = 0.0;
            for (e = 0; e < 3; e++)
                out[3 * a + b] += A[3 * a + e] * (transpose_b ? B[3 * b + e] : B[3 * e + b]);
        }
}

/* R M into M (3 x 3, row-major), kept a rotation (orthonormal). */
static void turn_by(const double *R, double *M) {
    double copy[9];
    memcpy(copy, M, sizeof copy);
    product(R, copy, 0, M);
    orthonormal(M);
}

/* Obstacle o's move y (3) and turn P = exp(th) S (9) at z. */
static void frame(const af_contact *c, const double *z, int o, double *y, double *P) {
    double th[3], R[9];
    motion(c, z, o, y, th);
    rotation_of(th, R);
    product(R, c->bodies[o].spun, 0, P);
}

/* Each free obstacle's frame at z kept (relative then reads it). */
static void prepare(af_contact *c, const double *z) {
    int o;
    for (o = 0; o < c->count; o++)
        if (is_free(c, o)) frame(c, z, o, c->bodies[o].moved, c->bodies[o].view);
}

/* Point x (3) seen from free obstacle o moved by y and turned by P (frame's), in its frame at
 * the step's start: x' = center + P^T v into out, v = x - center - y into v (3). */
static void seen(const af_contact *c, int o, const double *x, const double *y,
                 const double *P, double *out, double *v) {
    const body_t *b = c->bodies + o;
    double u[3];
    int a;
    for (a = 0; a < 3; a++) v[a] = x[a] - b->center[a] - y[a];
    transposed(P, v, u);
    for (a = 0; a < 3; a++) out[a] = b->center[a] + u[a];
}

/* Node i (placed) seen from obstacle o at the prepared point: x' into x, v into v (3 each). */
static void relative(const af_contact *c, int o, long i, double *x, double *v) {
    const double *at = c->xs + 3 * i, *center = c->bodies[o].center;
    if (is_free(c, o)) {
        seen(c, o, at, c->bodies[o].moved, c->bodies[o].view, x, v);
        return;
    }
    x[0] = at[0]; x[1] = at[1]; x[2] = at[2];
    v[0] = at[0] - center[0]; v[1] = at[1] - center[1]; v[2] = at[2] - center[2];
}

/* A term's gradient g (3) in x' of obstacle o, at a settled point (th = 0), as its gradients
 * in the node, gx = S g (the obstacle's move's: -gx), and in the obstacle's turn, gt = gx x v. */
static void carried_gradient(const af_contact *c, int o, const double *g, const double *v,
                             double *gx, double *gt) {
    int a;
    if (is_free(c, o)) times(c->bodies[o].spun, g, gx);
    else memcpy(gx, g, 3 * sizeof(double));
    for (a = 0; a < 3; a++) gt[a] = gx[(a + 1) % 3] * v[(a + 2) % 3] - gx[(a + 2) % 3] * v[(a + 1) % 3];
}

/* gx and gt (carried_gradient's) of a term of obstacle o at node i added: to the node's
 * gradient c->gs and to the obstacle's unknowns' in c->g. */
static void add_gradient(af_contact *c, int o, long i, const double *g, const double *v) {
    const body_t *b = c->bodies + o;
    double gx[3], gt[3];
    int a;
    carried_gradient(c, o, g, v, gx, gt);
    for (a = 0; a < 3; a++) c->gs[3 * i + a] += gx[a];
    if (!is_free(c, o)) return;
    for (a = 0; a < 3; a++) {
        c->g[b->slot + a] -= gx[a] / sqrt(b->mass);
        if (turns(b)) c->g[b->slot + 3 + a] += gt[a] / b->scale;
    }
}

/* A term's gradient g (3) in x' at a node of obstacle o (v: from its center) added to the
 * obstacle's wrench about its center: the force gx, the moment v x gx. */
static void push_on(af_contact *c, int o, const double *g, const double *v) {
    double gx[3], gt[3];
    int a;
    carried_gradient(c, o, g, v, gx, gt);
    for (a = 0; a < 3; a++) {
        c->wrench[6 * o + a] += gx[a];
        c->wrench[6 * o + 3 + a] -= gt[a];
    }
}

/* The rotation vector log(R) (3) of a row-major rotation R. */
static void log_of(const double *R, double *th) {
    double cosine = 0.5 * (R[0] + R[4] + R[8] - 1.0), angle, w[3], sine, f;
    w[0] = 0.5 * (R[7] - R[5]);
    w[1] = 0.5 * (R[2] - R[6]);
    w[2] = 0.5 * (R[3] - R[1]);
    sine = norm3(w);
    angle = atan2(sine, cosine < -1.0 ? -1.0 : cosine > 1.0 ? 1.0 : cosine);
    f = sine > 1e-8 ? angle / sine : 1.0 + sine * sine / 6.0;
    th[0] = f * w[0];
    th[1] = f * w[1];
    th[2] = f * w[2];
}

/* The inverse left Jacobian of log at th (3 x 3): d log(exp(delta) exp(th)) / d delta at 0. */
static void inverse_jacobian(const double *th, double *J) {
    double angle = norm3(th);
    series(th, -0.5, angle > 1e-4 ? 1.0 / (angle * angle) - (1.0 + cos(angle))
                                      / (2.0 * angle * sin(angle))
                                  : 1.0 / 12.0 + angle * angle / 720.0, J);
}

/* The left Jacobian of exp at th (3 x 3): the inverse of inverse_jacobian's. */
static void left_jacobian(const double *th, double *J) {
    double angle = norm3(th);
    series(th, angle > 1e-4 ? (1.0 - cos(angle)) / (angle * angle) : 0.5 - angle * angle / 24.0,
           angle > 1e-4 ? (angle - sin(angle)) / (angle * angle * angle)
                        : 1.0 / 6.0 - angle * angle / 120.0, J);
}

/* Obstacle o's whole turn in this step at z: log(exp(th) S). */
static void whole_turn(const af_contact *c, const double *z, int o, double *turn) {
    double y[3], P[9];
    frame(c, z, o, y, P);
    log_of(P, turn);
}

void af_contact_settle(af_contact *c, double *z) {
    double y[3], P[9];
    int o, a;
    for (o = 0; o < c->count; o++) {
        body_t *b = c->bodies + o;
        if (!is_free(c, o) || !turns(b)) continue;
        frame(c, z, o, y, P);
        memcpy(b->spun, P, sizeof P);
        for (a = 0; a < 3; a++) z[b->slot + 3 + a] = 0.0;
    }
}

/* The largest s in [0, 1] keeping x + s dx above floor from obstacle o (x starts above). */
static double first_touch(const af_contact *c, int o, const double *x, const double *dx,
                          double floor) {
    double s = 0.0, y[3], n[3];
    int it, a;
    for (it = 0; it < TOUCH_ITERATIONS; it++) {
        double phi, slope = 0.0, target;
        for (a = 0; a < 3; a++) y[a] = x[a] + s * dx[a];
        phi = distance(c, o, y, n, NULL) - floor;
        for (a = 0; a < 3; a++) slope += n[a] * dx[a];
        if (slope >= 0.0) return 1.0;           /* convex: never closer from here on */
        target = s - phi / slope;
        s = target < 1.0 ? target : 1.0;
        if (target >= 1.0 || phi <= TOUCH_TOLERANCE * floor) break;
    }
    return s;
}

/* The share of the step p (n) from z (nodes placed; z + p in c->qt, the nodes' moves in c->ds)
 * keeping every node at KEEP of its distance from each obstacle, along the straight line
 * between where it is seen from the obstacle before and after. */
static double share_of(const af_contact *c, const double *z) {
    double share = 1.0, n[3], x0[3], x1[3], d3[3], v[3], y0[3], P0[9], y1[3], P1[9], moved[3];
    long i;
    int o, a;
    for (o = 0; o < c->count; o++) {
        frame(c, z, o, y0, P0);
        frame(c, c->qt, o, y1, P1);
        for (i = 0; i < c->k; i++) {
            double s;
            if (is_free(c, o)) {
                for (a = 0; a < 3; a++) moved[a] = c->xs[3 * i + a] + c->ds[3 * i + a];
                seen(c, o, c->xs + 3 * i, y0, P0, x0, v);
                seen(c, o, moved, y1, P1, x1, v);
                for (a = 0; a < 3; a++) d3[a] = x1[a] - x0[a];
            } else {
                memcpy(x0, c->xs + 3 * i, sizeof x0);
                memcpy(d3, c->ds + 3 * i, sizeof d3);
            }
            if (d3[0] * d3[0] + d3[1] * d3[1] + d3[2] * d3[2] <= 0.0) continue;
            s = first_touch(c, o, x0, d3, KEEP * distance(c, o, x0, n, NULL));
            if (s < share) share = s;
        }
    }
    return share;
}

/* Obstacle o turned by R (row-major) about the point at (3) and moved by y: its geometry's
 * points and directions, its center and its turn from the file's. */
static void carry(af_contact *c, int o, const double *at, const double *y, const double *R) {
    double *G = c->geometry + o * GEOMETRY, *points[3], p[3], pin[3];
    int a, e, kind = c->kinds[o], count = 0;
    memcpy(pin, at, sizeof pin);                   /* at may be one of the points */
    points[count++] = c->bodies[o].center;
    points[count++] = G;                           /* a center, a plane's point, an end */
    if (kind == AF_CAPSULE) points[count++] = G + 3;
    for (e = 0; e < count; e++) {
        for (a = 0; a < 3; a++) p[a] = points[e][a] - pin[a];
        times(R, p, points[e]);
        for (a = 0; a < 3; a++) points[e][a] += pin[a] + y[a];
    }
    if (kind == AF_PLANE) {                        /* its normal turns */
        memcpy(p, G + 3, sizeof p);
        times(R, p, G + 3);
    }
    if (kind == AF_BOX) turn_by(R, G + 6);         /* its axes turn */
    turn_by(R, c->bodies[o].turned);
}

/* Obstacle o turned to its target (af_contact_turn) about its position where no node then
 * comes within KEEP of its distance from it (else it waits for a later step's target). */
static void turn_to_target(af_contact *c, int o) {
    body_t *b = c->bodies + o;
    double R[9], G[GEOMETRY], turned[9], center[3], still[3] = {0.0, 0.0, 0.0}, n[3];
    long i;
    int clear = 1;
    b->turning = 0;
    product(b->target, b->turned, 1, R);   /* R = target turned^T */
    memcpy(G, c->geometry + o * GEOMETRY, sizeof G);
    memcpy(turned, b->turned, sizeof turned);
    memcpy(center, b->center, sizeof center);
    for (i = 0; i < c->k; i++) c->ds[i] = distance(c, o, c->xs + 3 * i, n, NULL);
    carry(c, o, G, still, R);
    for (i = 0; i < c->k && clear; i++)
        clear = distance(c, o, c->xs + 3 * i, n, NULL) > KEEP * c->ds[i];
    if (clear) return;
    memcpy(c->geometry + o * GEOMETRY, G, sizeof G);
    memcpy(b->turned, turned, sizeof turned);
    memcpy(b->center, center, sizeof center);
}

void af_contact_start(af_contact *c, const double *q, double dt) {
    long i;
    int o, a;
    double n[3];
    c->extra = 0;
    place(c, q);
    for (o = 0; o < c->count; o++) {   /* obstacles toward their targets, the body held */
        double *G = c->geometry + o * GEOMETRY, delta[3], share;
        body_t *b = c->bodies + o;
        b->slot = -1;
        for (a = 0; a < 9; a++) b->spun[a] = a % 4 == 0 ? 1.0 : 0.0;
        for (a = 0; a < 3; a++) c->shift[3 * o + a] = 0.0;
        if (b->turning) turn_to_target(c, o);
        if (!c->moving[o]) continue;
        for (a = 0; a < 3; a++) delta[a] = c->target[3 * o + a] - G[a];
        for (i = 0; i < c->k; i++)
            for (a = 0; a < 3; a++) c->ds[3 * i + a] = -delta[a];
        share = 1.0;
        for (i = 0; i < c->k; i++) {
            double s = first_touch(c, o, c->xs + 3 * i, c->ds + 3 * i,
                                   KEEP * distance(c, o, c->xs + 3 * i, n, NULL));
            if (s < share) share = s;
        }
        for (a = 0; a < 3; a++) {
            G[a] += share * delta[a];
            c->shift[3 * o + a] = share * delta[a];
            if (c->kinds[o] == AF_CAPSULE) G[3 + a] += share * delta[a];
            b->center[a] += share * delta[a];
        }
        c->moving[o] = share < 1.0;
    }
    for (o = 0; o < c->count; o++) {     /* a center set anew: from where it is now */
        body_t *b = c->bodies + o;
        for (a = 0; b->fresh && a < 3; a++)
            b->center[a] = c->geometry[o * GEOMETRY + a] + b->offset[a];
        b->fresh = 0;
    }
    c->lagged = 0;
    c->eps = c->smoothing * dt;
    c->inertia = dt > 0.0 ? 1.0 / (dt * dt) : 0.0;
    if (!(dt > 0.0)) return;
    for (o = 0; o < c->count; o++) {     /* the free obstacles' unknowns and predictions */
        body_t *b = c->bodies + o;
        if (!(b->mass > 0.0)) continue;
        b->slot = (int)(c->r + c->extra);
        c->extra += turns(b) ? 6 : 3;
        for (a = 0; a < 6; a++) b->hat[a] = dt * b->velocity[a] + dt * dt * b->push[a];
    }
    for (o = 0; o < c->count; o++) {
        double mu = c->friction[o] < 0.0 ? c->mu : c->friction[o];
        if (mu <= 0.0) continue;
        for (i = 0; i < c->k; i++) {
            double d = distance(c, o, c->xs + 3 * i, n, NULL);
            lag_t *l = c->lags + c->lagged;
            int b;
            if (!(d > 0.0 && d < c->dhat)) continue;
            l->node = (int)i;
            l->obstacle = o;
            l->weight = mu * -c->kappa * c->area[i] * barrier_slope(d, c->dhat);
            for (a = 0; a < 3; a++) {
                l->start[a] = c->xs[3 * i + a] + c->shift[3 * o + a];
                for (b = 0; b < 3; b++) l->T[3 * a + b] = (a == b) - n[a] * n[b];
            }
            c->lagged++;
        }
    }
}

/* Lag l's tangential slip u (3) at z (nodes placed), returning its length; the node seen from
 * its obstacle's v into v. */
static double slip(const af_contact *c, const lag_t *l, double *u, double *v) {
    double x[3], y = 0.0;
    int a, b;
    relative(c, l->obstacle, l->node, x, v);
    for (a = 0; a < 3; a++) {
        u[a] = 0.0;
        for (b = 0; b < 3; b++) u[a] += l->T[3 * a + b] * (x[b] - l->start[b]);
        y += u[a] * u[a];
    }
    return sqrt(y);
}

/* The energy at z (nodes placed), inf where a node reached an obstacle; with grad, its
 * gradient in the nodes into c->gs and in the free obstacles' unknowns into c->g[r:]. */
static double surface_energy(af_contact *c, const double *z, int grad) {
    double total = 0.0, n[3], x[3], v[3], f[3];
    long i, j;
    int o, a;
    if (grad) {   /* at a settled point: a turn's derivatives are taken at delta = 0 */
        memset(c->gs, 0, (size_t)c->k * 3 * sizeof(double));
        memset(c->g + c->r, 0, (size_t)c->extra * sizeof(double));
        memset(c->wrench, 0, (size_t)c->count * 6 * sizeof(double));
    }
    prepare(c, z);
    for (o = 0; o < c->count; o++) {
        int still = !is_free(c, o);        /* the node as it is, its gradient as it is */
        for (i = 0; i < c->k; i++) {
            double d, s;
            if (still) memcpy(x, c->xs + 3 * i, sizeof x);
            else relative(c, o, i, x, v);
            d = distance(c, o, x, n, NULL);
            if (d <= 0.0) return INFINITY;
            if (d >= c->dhat) continue;
            total += c->kappa * c->area[i] * barrier(d, c->dhat);
            if (!grad) continue;
            s = c->kappa * c->area[i] * barrier_slope(d, c->dhat);
            for (a = 0; a < 3; a++) f[a] = s * n[a];
            if (still)
                for (a = 0; a < 3; a++) {
                    c->gs[3 * i + a] += f[a];
                    v[a] = x[a] - c->bodies[o].center[a];
                }
            else
                add_gradient(c, o, i, f, v);
            push_on(c, o, f, v);
        }
    }
    for (j = 0; j < c->lagged; j++) {
        const lag_t *l = c->lags + j;
        double u[3], e = c->eps, s = slip(c, l, u, v), w;
        total += l->weight * (s < e ? -s * s * s / (3 * e * e) + s * s / e + e / 3.0 : s);
        w = l->weight * friction_slope(s, e);
        for (a = 0; a < 3; a++) f[a] = w * u[a];
        if (!grad) continue;
        add_gradient(c, l->obstacle, l->node, f, v);
        push_on(c, l->obstacle, f, v);
    }
    for (o = 0; o < c->count; o++) {        /* the free obstacles' inertia */
        const body_t *b = c->bodies + o;
        double diff[3], turn[3], J[9], Id[3];
        if (!is_free(c, o)) continue;
        for (a = 0; a < 3; a++) {
            diff[a] = z[b->slot + a] - sqrt(b->mass) * b->hat[a];
            total += 0.5 * c->inertia * diff[a] * diff[a];
            if (grad) c->g[b->slot + a] += c->inertia * diff[a];
        }
        if (!turns(b)) continue;
        whole_turn(c, z, o, turn);              /* (theta - theta_hat)^T I (...) / (2 dt^2) */
        for (a = 0; a < 3; a++) diff[a] = turn[a] - b->hat[3 + a];
        times(b->inertia, diff, Id);
        total += 0.5 * c->inertia * (diff[0] * Id[0] + diff[1] * Id[1] + diff[2] * Id[2]);
        if (!grad) continue;
        inverse_jacobian(turn, J);              /* its gradient in delta: J^T I (...) */
        transposed(J, Id, diff);
        for (a = 0; a < 3; a++) c->g[b->slot + 3 + a] += c->inertia * diff[a] / b->scale;
    }
    return total;
}

double af_contact_energy(af_contact *c, const double *z) {
    place(c, z);
    return surface_energy(c, z, 0);
}

/* Node i's Hessian (barrier and friction) and gradient in x' from each obstacle, at the point
 * prepare was last given, into c->blocks (count, 9) and c->pulls (count, 3); 0 where no term
 * touches it. */
static int node_blocks(af_contact *c, long i) {
    double n[3], curvature[9], x[3], v[3];
    long j;
    int o, a, b, live = 0;
    memset(c->blocks, 0, (size_t)c->count * 9 * sizeof(double));
    memset(c->pulls, 0, (size_t)c->count * 3 * sizeof(double));
    for (o = 0; o < c->count; o++) {
        double d, b1, b2, ka, *Bo = c->blocks + 9 * o;
        relative(c, o, i, x, v);
        d = distance(c, o, x, n, curvature);
        if (!(d > 0.0 && d < c->dhat)) continue;
        b1 = barrier_slope(d, c->dhat);
        b2 = barrier_curvature(d, c->dhat);
        ka = c->kappa * c->area[i];
        for (a = 0; a < 3; a++) {
            c->pulls[3 * o + a] += ka * b1 * n[a];
            for (b = 0; b < 3; b++)
                Bo[3 * a + b] += ka * (b2 * n[a] * n[b] + b1 * curvature[3 * a + b]);
        }
        live = 1;
    }
    for (j = 0; j < c->lagged; j++) {
        const lag_t *l = c->lags + j;
        double u[3], unit[3], y, e = c->eps, along, f1, *Bo = c->blocks + 9 * l->obstacle;
        if (l->node != i) continue;
        y = slip(c, l, u, v);
        for (a = 0; a < 3; a++) unit[a] = u[a] / (y > 1e-300 ? y : 1e-300);
        along = y < e ? -y / (e * e) : -1.0 / (y > 1e-300 ? y : 1e-300);
        f1 = friction_slope(y, e);
        for (a = 0; a < 3; a++) {
            c->pulls[3 * l->obstacle + a] += l->weight * f1 * u[a];
            for (b = 0; b < 3; b++)
                Bo[3 * a + b] += l->weight * (f1 * l->T[3 * a + b] + along * unit[a] * unit[b]);
        }
        live = 1;
    }
    return live;
}

/* C (3 x 3) = A^T B C' for 3 x 3 row-major A, B, C'. */
static void sandwich(const double *A, const double *B, const double *Cp, double *C) {
    double BC[9];
    int a, b, e;
    for (a = 0; a < 3; a++)
        for (b = 0; b < 3; b++) {
            BC[3 * a + b] = 0.0;
            for (e = 0; e < 3; e++) BC[3 * a + b] += B[3 * a + e] * Cp[3 * e + b];
        }
    for (a = 0; a < 3; a++)
        for (b = 0; b < 3; b++) {
            C[3 * a + b] = 0.0;
            for (e = 0; e < 3; e++) C[3 * a + b] += A[3 * e + a] * BC[3 * e + b];
        }
}


/* Free obstacle o's block B (9) and gradient g (3) in x' as the node's: S B S^T and S g (S its
 * turn so far). */
static void node_view(const af_contact *c, int o, const double *B, const double *g,
                      double *Bx, double *gx) {
    const double *S = c->bodies[o].spun;
    double SB[9];
    product(S, B, 0, SB);
    product(SB, S, 1, Bx);
    times(S, g, gx);
}

double af_contact_terms(af_contact *c, const double *z, const double **g, const double **H,
                        double *floor) {
    long i, r = c->r, n = r + c->extra, s, t;
    int o, a, b;
    double energy, largest = 0.0, size = 0.0, *cg = c->g, *cH = c->H;
    place(c, z);
    energy = surface_energy(c, z, 1);     /* writes the free obstacles' part of g */
    memset(cg, 0, (size_t)r * sizeof(double));
    memset(cH, 0, (size_t)(n * n) * sizeof(double));
    for (i = 0; i < c->k; i++)
        for (a = 0; a < 3; a++) {
            const double *row = c->U + (3 * i + a) * r;
            double v = c->gs[3 * i + a];
            if (fabs(c->xs[3 * i + a]) > largest) largest = fabs(c->xs[3 * i + a]);
            if (v != 0.0)
                for (s = 0; s < r; s++) cg[s] += v * row[s];
        }
    for (i = 0; i < c->k; i++) {
        static const double identity[9] = {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0};
        double B[9] = {0}, W[3 * 64], *w, Bx[9], gx[3], Hxt[9], Htt[9], Jt[9], G[9], x[3], v[3];
        const double *U = c->U + 3 * i * r;
        if (!node_blocks(c, i)) continue;
        for (o = 0; o < c->count; o++) {          /* the node's block: the sum of its views */
            if (is_free(c, o)) node_view(c, o, c->blocks + 9 * o, c->pulls + 3 * o, Bx, gx);
            else memcpy(Bx, c->blocks + 9 * o, sizeof Bx);
            for (a = 0; a < 9; a++) B[a] += Bx[a];
        }
        w = r <= 64 ? W : (double *)malloc((size_t)(3 * r) * sizeof(double));
        if (!w) continue;
        for (a = 0; a < 3; a++)                   /* w = B U_i (3 x r) */
            for (s = 0; s < r; s++)
                w[a * r + s] = B[3 * a] * U[s] + B[3 * a + 1] * U[r + s]
                               + B[3 * a + 2] * U[2 * r + s];
        for (s = 0; s < r; s++)                   /* H += U_i^T w */
            for (t = 0; t < r; t++)
                cH[s * n + t] += U[s] * w[t] + U[r + s] * w[r + t] + U[2 * r + s] * w[2 * r + t];
        if (w != W) free(w);
        for (o = 0; o < c->count; o++) {          /* a free obstacle's blocks */
            const body_t *bo = c->bodies + o;
            long m = bo->slot;
            double root = sqrt(bo->mass), scale = bo->scale, gv;
            if (m < 0 || !c->extra) continue;
            node_view(c, o, c->blocks + 9 * o, c->pulls + 3 * o, Bx, gx);
            for (a = 0; a < 3; a++) {             /* q-move -U^T Bx / sqrt(m), move-move */
                for (s = 0; s < r; s++) {
                    double e = -(U[s] * Bx[a] + U[r + s] * Bx[3 + a]
                                 + U[2 * r + s] * Bx[6 + a]) / root;
                    cH[s * n + m + a] += e;
                    cH[(m + a) * n + s] += e;
                }
                for (b = 0; b < 3; b++) cH[(m + a) * n + m + b] += Bx[3 * a + b] / bo->mass;
            }
            if (!turns(bo)) continue;
            relative(c, o, i, x, v);           /* Hxt = Bx [v] - [gx] */
            cross_matrix(v, Jt);
            cross_matrix(gx, G);
            sandwich(identity, Bx, Jt, Hxt);
            for (a = 0; a < 9; a++) Hxt[a] -= G[a];
            sandwich(Jt, Bx, Jt, Htt);            /* Htt = [v]^T Bx [v] + the turn's curvature */
            gv = gx[0] * v[0] + gx[1] * v[1] + gx[2] * v[2];
            for (a = 0; a < 3; a++)
                for (b = 0; b < 3; b++)
                    Htt[3 * a + b] += 0.5 * (gx[a] * v[b] + v[a] * gx[b]) - (a == b) * gv;
            for (a = 0; a < 3; a++) {
                for (s = 0; s < r; s++) {         /* q-turn U^T Hxt / s */
                    double e = (U[s] * Hxt[a] + U[r + s] * Hxt[3 + a]
                                + U[2 * r + s] * Hxt[6 + a]) / scale;
                    cH[s * n + m + 3 + a] += e;
                    cH[(m + 3 + a) * n + s] += e;
                }
                for (b = 0; b < 3; b++) {          /* move-turn -Hxt, turn-turn Htt */
                    double e = -Hxt[3 * a + b] / (root * scale);
                    cH[(m + a) * n + m + 3 + b] += e;
                    cH[(m + 3 + b) * n + m + a] += e;
                    cH[(m + 3 + a) * n + m + 3 + b] += Htt[3 * a + b] / (scale * scale);
                }
            }
        }
    }
    for (o = 0; o < c->count; o++) {             /* their inertia */
        const body_t *bo = c->bodies + o;
        double turn[3], J[9], IJ[9];
        if (!is_free(c, o)) continue;
        for (a = 0; a < 3; a++) cH[(bo->slot + a) * (n + 1)] += c->inertia;
        if (!turns(bo)) continue;
        whole_turn(c, z, o, turn);                /* J^T I J (Gauss-Newton in the turn) */
        inverse_jacobian(turn, J);
        sandwich(J, bo->inertia, J, IJ);
        for (a = 0; a < 3; a++)
            for (b = 0; b < 3; b++)
                cH[(bo->slot + 3 + a) * n + bo->slot + 3 + b] +=
                    c->inertia * IJ[3 * a + b] / (bo->scale * bo->scale);
    }
    for (s = 0; s < n * n; s++) size += cH[s] * cH[s];
    *floor = largest * sqrt(size);
    *g = cg;
    *H = cH;
    return energy;
}

double af_contact_change(af_contact *c, const double *z, const double *step, double energy) {
    long i, n = c->r + c->extra;
    double after, linear = af_dot(c->g, step, n), big;
    for (i = 0; i < n; i++) c->qt[i] = z[i] + step[i];
    after = af_contact_energy(c, c->qt);
    if (!isfinite(after)) return after;     /* a node reached an obstacle */
    big = fabs(after) > fabs(energy) ? fabs(after) : fabs(energy);
    return fabs(after - energy - linear) <= NOISE * big ? linear : after - energy;
}

double af_contact_limit(af_contact *c, const double *z, const double *p) {
    long i, a, r = c->r, n = r + c->extra;
    for (i = 0; i < n; i++) c->qt[i] = z[i] + p[i];
    place(c, z);
    for (i = 0; i < c->k; i++)
        for (a = 0; a < 3; a++) c->ds[3 * i + a] = af_dot(c->U + (3 * i + a) * r, p, r);
    return share_of(c, z);
}

void af_contact_finish(af_contact *c, const double *z, double dt) {
    double x[3], y[3], th[3];
    int o, a;
    place(c, z);                 /* the wrench: from the gradient's last evaluation, at z */
    prepare(c, z);
    for (o = 0; o < c->count; o++) {     /* the free ones moved and turned, at their speed */
        body_t *b = c->bodies + o;
        double turn[3], J[9], *M = c->wrench + 6 * o + 3;
        if (!is_free(c, o)) continue;
        motion(c, z, o, y, th);
        whole_turn(c, z, o, turn);
        if (turns(b)) {  /* the moment that turns it as the step did: J_l(turn)^T M */
            left_jacobian(turn, J);
            transposed(J, M, x);
            memcpy(M, x, 3 * sizeof(double));
        }
        carry(c, o, b->center, y, b->spun);
        for (a = 0; a < 3; a++) {
            b->velocity[a] = y[a] / dt;
            b->velocity[3 + a] = turns(b) ? turn[a] / dt : 0.0;
        }
    }
}

void af_contact_center(const af_contact *c, int i, double *center) {
    memcpy(center, c->bodies[i].center, 3 * sizeof(double));
}
