/* A reduced model's contact with rigid obstacles, as export/runtime.py's Contact steps it
 * (anisofem.physics.contact's method): the IPC barrier kappa A b(d), b(d) = -(d - dhat)^2
 * ln(d / dhat), at the surface nodes x_s = rest + U q; friction lagged at a step's start, mu
 * lambda f0(|T (x - x_n)|) with f0 smoothed below eps = smoothing dt; the largest share of a
 * step that keeps every node at KEEP of its distance from every obstacle (Newton on the convex
 * distance along the move, which never passes its first root). Obstacles: a plane, and a
 * sphere, box or capsule as a convex core grown by a radius; af_contact_move sets where one
 * is to be, reached as far as the body lets it at the next step's start.
 *
 * A free obstacle (af_contact_motion: a mass, its velocity and the acceleration all else
 * gives it) translates with the body: a step's unknowns are z = (q, sqrt(m) y), y (3 each) a
 * free obstacle's move over the step (mass-weighted like the basis's coordinates), their
 * inertia m |y - y_hat|^2 / (2 dt^2) (y_hat = dt v + dt^2 a) a term here, and every distance
 * taken from the node to the obstacle moved by y. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "af_internal.h"

#define KEEP 0.1
#define TOUCH_ITERATIONS 60
#define TOUCH_TOLERANCE 1e-3
#define GEOMETRY 15
#define NOISE 1e-12      /* the share of the energy below which two values are round-off */

typedef struct {
    int node, obstacle;          /* the surface node (row of contact_rest), the obstacle */
    double weight, T[9], start[3];
} lag_t;

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
    lag_t *lags;
    long lagged;
    char *names;                 /* the obstacles' names, each ended by a NUL */
    double *mass;                /* (count,) kg of a free obstacle, 0 for a moved one */
    double *velocity, *push;     /* (count, 3) its velocity, m/s, and acceleration, m/s^2 */
    int *slot;                   /* (count,) a free obstacle's first unknown in z, else -1 */
    long extra;                  /* this solve's unknowns beside q: 3 per free obstacle */
    double inertia;              /* this step's 1 / dt^2 */
    double *hat;                 /* (count, 3) a free obstacle's y_hat */
    double *wrench;              /* (count, 6) force on each, N, and its moment about its
                                    position, N m, at the last step's end */
    double *xs, *gs, *ds, *dy;   /* scratch (k, 3) each, (count, 3) */
    double *blocks;              /* scratch (count, 9): a node's Hessian from each obstacle */
    double *g, *H, *qt;          /* the terms' gradient (n), Hessian (n, n); a point (n),
                                    n = r + 3 count at most */
};

/* The move y (3, m) of obstacle o in z into y: zeros where it is not free; z holds a free
 * one's sqrt(m) y, its inertia then the q's |.|^2 / (2 dt^2) of the mass-orthonormal basis. */
static void moved(const af_contact *c, const double *z, int o, double *y) {
    int a;
    for (a = 0; a < 3; a++)
        y[a] = c->slot[o] >= 0 && c->extra ? z[c->slot[o] + a] / sqrt(c->mass[o]) : 0.0;
}

void af_contact_close(af_contact *c) {
    if (!c) return;
    free(c->rest); free(c->U); free(c->area); free(c->kinds); free(c->geometry);
    free(c->friction); free(c->target); free(c->shift); free(c->moving); free(c->lags);
    free(c->xs); free(c->mass); free(c->velocity); free(c->push); free(c->slot);
    free(c->hat); free(c->wrench); free(c->dy); free(c->blocks);
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
        size_t n = (size_t)r + 3 * (size_t)count;
        c->g = (double *)malloc((n + 1) * sizeof(double));
        c->H = (double *)malloc((n * n + 1) * sizeof(double));
        c->qt = (double *)malloc((n + 1) * sizeof(double));
    }
    c->mass = (double *)calloc((size_t)count + 1, sizeof(double));
    c->velocity = (double *)calloc((size_t)count * 3 + 1, sizeof(double));
    c->push = (double *)calloc((size_t)count * 3 + 1, sizeof(double));
    c->hat = (double *)calloc((size_t)count * 3 + 1, sizeof(double));
    c->dy = (double *)calloc((size_t)count * 3 + 1, sizeof(double));
    c->blocks = (double *)calloc((size_t)count * 9 + 1, sizeof(double));
    c->wrench = (double *)calloc((size_t)count * 6 + 1, sizeof(double));
    c->slot = (int *)malloc(((size_t)count + 1) * sizeof(int));
    for (i = 0; c->slot && i < count; i++) c->slot[i] = -1;
    if (!c->target || !c->shift || !c->moving || !c->lags || !c->xs || !c->gs || !c->ds ||
        !c->g || !c->H || !c->qt || !c->mass || !c->velocity || !c->push || !c->hat ||
        !c->dy || !c->blocks || !c->wrench || !c->slot) {
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

void af_contact_motion(af_contact *c, int i, double mass, const double *velocity,
                       const double *acceleration) {
    c->mass[i] = mass;
    memcpy(c->velocity + 3 * i, velocity, 3 * sizeof(double));
    memcpy(c->push + 3 * i, acceleration, 3 * sizeof(double));
}

const double *af_contact_wrench(const af_contact *c, int i) { return c->wrench + 6 * i; }

long af_contact_unknowns(const af_contact *c) { return c ? c->extra : 0; }

void af_contact_guess(const af_contact *c, double *y) {
    int o, a;
    for (o = 0; o < c->count; o++)
        for (a = 0; c->slot[o] >= 0 && a < 3; a++)
            y[c->slot[o] - c->r + a] = c->velocity[3 * o + a] * sqrt(c->mass[o] / c->inertia);
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

/* Node i (placed) seen from obstacle o moved by its y in z: x - y (3) into x. */
static void relative(const af_contact *c, const double *z, int o, long i, double *x) {
    double y[3];
    int a;
    moved(c, z, o, y);
    for (a = 0; a < 3; a++) x[a] = c->xs[3 * i + a] - y[a];
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

/* The share of the moves ds (k, 3) of the placed nodes and dy (count, 3) of the obstacles
 * from z keeping every node at KEEP of its distance. */
static double share_of(const af_contact *c, const double *z, const double *ds,
                       const double *dy) {
    double share = 1.0, n[3], x[3], d3[3];
    long i;
    int o, a;
    for (o = 0; o < c->count; o++)
        for (i = 0; i < c->k; i++) {
            double s;
            for (a = 0; a < 3; a++) d3[a] = ds[3 * i + a] - dy[3 * o + a];
            if (d3[0] * d3[0] + d3[1] * d3[1] + d3[2] * d3[2] <= 0.0) continue;
            relative(c, z, o, i, x);
            s = first_touch(c, o, x, d3, KEEP * distance(c, o, x, n, NULL));
            if (s < share) share = s;
        }
    return share;
}

void af_contact_start(af_contact *c, const double *q, double dt) {
    long i;
    int o, a;
    double n[3];
    c->extra = 0;
    place(c, q);
    for (o = 0; o < c->count; o++) {   /* obstacles toward their targets, the body held */
        double *G = c->geometry + o * GEOMETRY, delta[3], share;
        c->slot[o] = -1;
        for (a = 0; a < 3; a++) c->shift[3 * o + a] = 0.0;
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
        }
        c->moving[o] = share < 1.0;
    }
    c->lagged = 0;
    c->eps = c->smoothing * dt;
    c->inertia = dt > 0.0 ? 1.0 / (dt * dt) : 0.0;
    if (!(dt > 0.0)) return;
    for (o = 0; o < c->count; o++)       /* the free obstacles' unknowns and predictions */
        if (c->mass[o] > 0.0) {
            c->slot[o] = (int)(c->r + c->extra);
            c->extra += 3;
            for (a = 0; a < 3; a++)
                c->hat[3 * o + a] = dt * c->velocity[3 * o + a] + dt * dt * c->push[3 * o + a];
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

/* Lag l's tangential slip u (3) at z (nodes placed), returning its length. */
static double slip(const af_contact *c, const lag_t *l, const double *z, double *u) {
    double x[3], y = 0.0;
    int a, b;
    relative(c, z, l->obstacle, l->node, x);
    for (a = 0; a < 3; a++) {
        u[a] = 0.0;
        for (b = 0; b < 3; b++) u[a] += l->T[3 * a + b] * (x[b] - l->start[b]);
        y += u[a] * u[a];
    }
    return sqrt(y);
}

/* The energy at z (nodes placed), inf where a node reached an obstacle; with grad, its
 * gradient in the nodes into c->gs and in the free obstacles' moves into c->g[r:]. */
static double surface_energy(af_contact *c, const double *z, int grad) {
    double total = 0.0, n[3], x[3];
    long i, j;
    int o, a;
    if (grad) {
        memset(c->gs, 0, (size_t)c->k * 3 * sizeof(double));
        memset(c->g + c->r, 0, (size_t)c->extra * sizeof(double));
    }
    for (o = 0; o < c->count; o++) {
        double *gy = grad && c->slot[o] >= 0 ? c->g + c->slot[o] : NULL, root = sqrt(c->mass[o]);
        for (i = 0; i < c->k; i++) {
            double d, s;
            relative(c, z, o, i, x);
            d = distance(c, o, x, n, NULL);
            if (d <= 0.0) return INFINITY;
            if (d >= c->dhat) continue;
            total += c->kappa * c->area[i] * barrier(d, c->dhat);
            s = c->kappa * c->area[i] * barrier_slope(d, c->dhat);
            if (grad)
                for (a = 0; a < 3; a++) c->gs[3 * i + a] += s * n[a];
            if (gy)
                for (a = 0; a < 3; a++) gy[a] -= s * n[a] / root;
        }
    }
    for (j = 0; j < c->lagged; j++) {
        const lag_t *l = c->lags + j;
        double u[3], e = c->eps, y = slip(c, l, z, u), f;
        double *gy = grad && c->slot[l->obstacle] >= 0 ? c->g + c->slot[l->obstacle] : NULL;
        total += l->weight * (y < e ? -y * y * y / (3 * e * e) + y * y / e + e / 3.0 : y);
        f = l->weight * friction_slope(y, e);
        if (grad)
            for (a = 0; a < 3; a++) c->gs[3 * l->node + a] += f * u[a];
        if (gy)
            for (a = 0; a < 3; a++) gy[a] -= f * u[a] / sqrt(c->mass[l->obstacle]);
    }
    for (o = 0; o < c->count; o++)          /* the free obstacles' inertia */
        if (c->slot[o] >= 0 && c->extra) {
            const double *y = z + c->slot[o];
            for (a = 0; a < 3; a++) {
                double diff = y[a] - sqrt(c->mass[o]) * c->hat[3 * o + a];
                total += 0.5 * c->inertia * diff * diff;
                if (grad) c->g[c->slot[o] + a] += c->inertia * diff;
            }
        }
    return total;
}

double af_contact_energy(af_contact *c, const double *z) {
    place(c, z);
    return surface_energy(c, z, 0);
}

/* Node i's Hessian from each obstacle (barrier and friction) into c->blocks (count, 9) and
 * their sum into B (9); 0 where no term touches it. */
static int node_blocks(af_contact *c, const double *z, long i, double *B) {
    double n[3], curvature[9], x[3];
    long j;
    int o, a, b, live = 0;
    memset(c->blocks, 0, (size_t)c->count * 9 * sizeof(double));
    for (o = 0; o < c->count; o++) {
        double d, b1, b2, ka, *Bo = c->blocks + 9 * o;
        relative(c, z, o, i, x);
        d = distance(c, o, x, n, curvature);
        if (!(d > 0.0 && d < c->dhat)) continue;
        b1 = barrier_slope(d, c->dhat);
        b2 = barrier_curvature(d, c->dhat);
        ka = c->kappa * c->area[i];
        for (a = 0; a < 3; a++)
            for (b = 0; b < 3; b++)
                Bo[3 * a + b] += ka * (b2 * n[a] * n[b] + b1 * curvature[3 * a + b]);
        live = 1;
    }
    for (j = 0; j < c->lagged; j++) {
        const lag_t *l = c->lags + j;
        double u[3], unit[3], y, e = c->eps, along, f1, *Bo = c->blocks + 9 * l->obstacle;
        if (l->node != i) continue;
        y = slip(c, l, z, u);
        for (a = 0; a < 3; a++) unit[a] = u[a] / (y > 1e-300 ? y : 1e-300);
        along = y < e ? -y / (e * e) : -1.0 / (y > 1e-300 ? y : 1e-300);
        f1 = friction_slope(y, e);
        for (a = 0; a < 3; a++)
            for (b = 0; b < 3; b++)
                Bo[3 * a + b] += l->weight * (f1 * l->T[3 * a + b] + along * unit[a] * unit[b]);
        live = 1;
    }
    memset(B, 0, 9 * sizeof(double));
    for (o = 0; live && o < c->count; o++)
        for (a = 0; a < 9; a++) B[a] += c->blocks[9 * o + a];
    return live;
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
        double B[9], W[3 * 64], *w;
        const double *U = c->U + 3 * i * r;
        if (!node_blocks(c, z, i, B)) continue;
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
        for (o = 0; o < c->count; o++) {   /* a free obstacle's: -U_i^T B_o, B_o, over sqrt(m) */
            const double *Bo = c->blocks + 9 * o;
            long y = c->slot[o];
            double root = y >= 0 ? sqrt(c->mass[o]) : 1.0;
            if (y < 0) continue;
            for (a = 0; a < 3; a++) {
                for (s = 0; s < r; s++) {
                    double v = -(U[s] * Bo[a] + U[r + s] * Bo[3 + a] + U[2 * r + s] * Bo[6 + a])
                               / root;
                    cH[s * n + y + a] += v;
                    cH[(y + a) * n + s] += v;
                }
                for (b = 0; b < 3; b++) cH[(y + a) * n + y + b] += Bo[3 * a + b] / c->mass[o];
            }
        }
    }
    for (o = 0; o < c->count; o++)
        if (c->slot[o] >= 0)
            for (a = 0; a < 3; a++) cH[(c->slot[o] + a) * (n + 1)] += c->inertia;
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
    big = fabs(after) > fabs(energy) ? fabs(after) : fabs(energy);
    return fabs(after - energy - linear) <= NOISE * big ? linear : after - energy;
}

double af_contact_limit(af_contact *c, const double *z, const double *p) {
    long i, a, r = c->r;
    int o;
    place(c, z);
    for (i = 0; i < c->k; i++)
        for (a = 0; a < 3; a++) c->ds[3 * i + a] = af_dot(c->U + (3 * i + a) * r, p, r);
    for (o = 0; o < c->count; o++) moved(c, p, o, c->dy + 3 * o);
    return share_of(c, z, c->ds, c->dy);
}

/* wrench (6) += the force f (3) at arm (3) from the point it is taken about. */
static void add_wrench(double *wrench, const double *arm, const double *f) {
    wrench[0] += f[0]; wrench[1] += f[1]; wrench[2] += f[2];
    wrench[3] += arm[1] * f[2] - arm[2] * f[1];
    wrench[4] += arm[2] * f[0] - arm[0] * f[2];
    wrench[5] += arm[0] * f[1] - arm[1] * f[0];
}

void af_contact_finish(af_contact *c, const double *z, double dt) {
    double n[3], x[3], arm[3];
    long i, j;
    int o, a;
    place(c, z);
    memset(c->wrench, 0, (size_t)c->count * 6 * sizeof(double));
    for (o = 0; o < c->count; o++)         /* each one's push on the nodes, reversed */
        for (i = 0; i < c->k; i++) {
            double d, s, f[3];
            relative(c, z, o, i, x);
            d = distance(c, o, x, n, NULL);
            if (!(d > 0.0 && d < c->dhat)) continue;
            s = c->kappa * c->area[i] * barrier_slope(d, c->dhat);
            for (a = 0; a < 3; a++) f[a] = s * n[a];
            for (a = 0; a < 3; a++) arm[a] = x[a] - c->geometry[o * GEOMETRY + a];
            add_wrench(c->wrench + 6 * o, arm, f);
        }
    for (j = 0; j < c->lagged; j++) {
        const lag_t *l = c->lags + j;
        double u[3], f[3], y = slip(c, l, z, u), w = l->weight * friction_slope(y, c->eps);
        relative(c, z, l->obstacle, l->node, x);
        for (a = 0; a < 3; a++) {
            f[a] = w * u[a];
            arm[a] = x[a] - c->geometry[l->obstacle * GEOMETRY + a];
        }
        add_wrench(c->wrench + 6 * l->obstacle, arm, f);
    }
    for (o = 0; o < c->count; o++) {     /* the free obstacles moved, at their new speed */
        double *G = c->geometry + o * GEOMETRY, y[3];
        if (c->slot[o] < 0 || !c->extra) continue;
        moved(c, z, o, y);
        for (a = 0; a < 3; a++) {
            G[a] += y[a];
            if (c->kinds[o] == AF_CAPSULE) G[3 + a] += y[a];
            c->velocity[3 * o + a] = y[a] / dt;
        }
    }
}
