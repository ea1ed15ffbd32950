/* anisofem's soft body as a MuJoCo engine plugin ("anisofem.soft"): a model file written by
 * `python -m export reduced [--framed]`, stepped by this runtime (anisofem.h) as MuJoCo
 * steps, carried by the body that names the plugin's instance (export/README.md, "In
 * MuJoCo"; export/mujoco.py builds and registers it).
 *
 *   <extension>
 *     <plugin plugin="anisofem.soft">
 *       <instance name="finger">
 *         <config key="file" value="models/finger"/>   <!-- path without extension -->
 *         <config key="timestep" value="0.01"/>         <!-- the soft step, s (MuJoCo's) -->
 *         <config key="substeps" value="1"/>            <!-- each divided in this many -->
 *       </instance>
 *     </plugin>
 *   </extension>
 *   <worldbody> <body name="hand" pos="0 0 0.5"> <plugin instance="finger"/> </body> </worldbody>
 *   <actuator> <plugin name="push" instance="finger" site="..."/> </actuator>  <!-- a control -->
 *
 * The file's coordinates are the carrying body's: its held vertices sit where the body puts
 * them, x = R_body x0 + p_body. A reduced (linear) model's move with a body that translates
 * (slide joints only; its step is taken in the body's frame, the body's acceleration an
 * inertial force); a framed model's with a body that moves in any way. Gravity is MuJoCo's.
 *
 * Passive: the soft state lives in MuJoCo's plugin state (mjData.plugin_state, saved and reset
 * with it). The first passive forces after a reset place it at rest where its body is. A
 * framed model steps to where its body has moved: each time the passive forces are computed
 * a `timestep` past the soft state's (default: once per mj_step), in `substeps` backward-Euler
 * steps, the held vertices where the body is then. A reduced model steps ahead over the next
 * `timestep` whenever MuJoCo's time reaches its state's, so that the forces it puts on the
 * bodies it touches act over the same MuJoCo steps. Its controls are its actuators' ctrl, and
 * each obstacle of the file a geom is named for follows the geom: a geom on a free body (a
 * free joint) is a free obstacle, its move and turn solved with the soft step from the body's
 * velocity and what else pushed it over the last step, and the soft body's force and moment
 * on it applied at its centre of mass over the step; any other geom moves its obstacle by the
 * geom's translation. Where the carrier moves, the soft body pulls it
 * back by the impulse the carrier gave it (the soft body's momentum change less gravity's and
 * the obstacles' impulses). Actuator: the plugin's actuators only carry controls (they push
 * nothing). Visualize: the surface, drawn as MuJoCo draws a flex (faces, edges).
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <mujoco/mujoco.h>

#include "anisofem.h"

/* The plugin state: the time the soft state is at (UNPLACED until the first passive forces
 * place it where its body is), the length of its last step, s, the soft body's pull on its
 * carrier over the step before (a force, N, and its moment about the world's origin, N m),
 * where the carrier was at the last step's start and its velocity there (m, m/s), the
 * obstacles' impulse on the soft body over the last step (in the file's coordinates: N s, and
 * its moment about the file's origin, N m s), then the runtime's state, then per obstacle its
 * body's velocity at the last step's start (its center of mass's, m/s, NAN before one; its
 * spin, rad/s) and the soft body's force (N) and moment about that center (N m) on it now. */
enum { AT = 0, STEP = 1, PULL = 2, CARRIED = 8, TOUCHED = 14, HEADER = 20 };
enum { OBSTACLE = 12, FROM = 15 };
#define UNPLACED (-1.0)

typedef struct {
    af_model *model;
    int body;      /* the body that carries it */
    int substeps;
    double timestep; /* the soft step, s; 0: MuJoCo's */
    int n;
    int free;      /* whether the carrier moves: only then does the soft body pull it */
    double *x, *v; /* the vertices' positions (m) and velocities (m/s) at the state's time */
    int nedge;     /* the surface's edges, drawn in MuJoCo's scene */
    int *edges;
    int *geom;     /* per obstacle of the file, the geom named as it (-1: none) */
    int *owner;    /* per obstacle, the free body its geom is on (-1: none) */
    double *from;  /* per obstacle: where it was, in the file, and its geom in the world
                      (position, then rotation) when the soft body was placed (FROM each) */
    double placed[3]; /* where the carrier was then */
    double *scratch, *values; /* room for n positions, and for the controls */
} soft;

static const char *attributes[] = {"file", "substeps", "timestep"};

/* The model file the instance names, loaded; NULL with the reason in error. */
static af_model *load(const mjModel *m, int instance, char *error, size_t size) {
    const char *file = mj_getPluginConfig(m, instance, "file");
    char why[512];
    af_model *model;
    if (!file || !*file) {
        snprintf(error, size, "anisofem.soft: no 'file' in the instance's config (the model "
                 "file's path without extension, written by python -m export reduced)");
        return NULL;
    }
    model = af_load(file, NULL, why, sizeof why);
    if (!model)
        snprintf(error, size, "anisofem.soft: %s: %s", file, why);
    return model;
}

/* The body whose <plugin instance=...> names this instance, or -1. */
static int carrier(const mjModel *m, int instance) {
    for (int b = 0; b < m->nbody; b++)
        if (m->body_plugin[b] == instance)
            return b;
    return -1;
}

/* Whether body b moves: a joint on it or on a body it hangs from, or a mocap body. */
static int moves(const mjModel *m, int b) {
    for (; b > 0; b = m->body_parentid[b])
        if (m->body_jntnum[b] > 0 || m->body_mocapid[b] >= 0)
            return 1;
    return 0;
}

/* Whether body b can turn: a joint other than a slide on it or a body it hangs from, or a
 * mocap body. */
static int turns(const mjModel *m, int b) {
    for (; b > 0; b = m->body_parentid[b]) {
        if (m->body_mocapid[b] >= 0)
            return 1;
        for (int j = 0; j < m->body_jntnum[b]; j++)
            if (m->jnt_type[m->body_jntadr[b] + j] != mjJNT_SLIDE)
                return 1;
    }
    return 0;
}

/* The body geom g is on where that body hangs from the world by a free joint, else -1. */
static int free_body(const mjModel *m, int g) {
    int b = m->geom_bodyid[g];
    return b > 0 && m->body_parentid[b] == 0 && m->body_jntnum[b] == 1
           && m->jnt_type[m->body_jntadr[b]] == mjJNT_FREE ? b : -1;
}

static int substeps(const mjModel *m, int instance, char *error, size_t size) {
    const char *text = mj_getPluginConfig(m, instance, "substeps");
    char *end;
    long count;
    if (!text || !*text)
        return 1;
    count = strtol(text, &end, 10);
    if (*end || count < 1 || count > 10000) {
        snprintf(error, size, "anisofem.soft: substeps: expected a whole number from 1 to "
                 "10000, got '%s'", text);
        return -1;
    }
    return (int)count;
}

/* The soft step the instance asks for, s (0: MuJoCo's), or -1 with error saying why not. */
static double timestep(const mjModel *m, int instance, char *error, size_t size) {
    const char *text = mj_getPluginConfig(m, instance, "timestep");
    char *end;
    double dt;
    if (!text || !*text)
        return 0.0;
    dt = strtod(text, &end);
    if (*end || !(dt > 0.0) || !(dt < 1e3)) {
        snprintf(error, size, "anisofem.soft: timestep: expected a time step > 0 s, got '%s'",
                 text);
        return -1.0;
    }
    return dt;
}

/* The model's control named by actuator a of the instance, or -1. */
static int control_of(const mjModel *m, int a, const af_model *model) {
    const char *name = mj_id2name(m, mjOBJ_ACTUATOR, a);
    for (int i = 0; name && i < af_controls(model); i++)
        if (!strcmp(name, af_control_name(model, i)))
            return i;
    return -1;
}

/* Whether every actuator of the instance is named as one of the model's controls; else 0
 * with error saying which is not and what the controls are. */
static int controls_named(const mjModel *m, int instance, const af_model *model, char *error,
                          size_t size) {
    for (int a = 0; a < m->nu; a++) {
        if (m->actuator_plugin[a] != instance || control_of(m, a, model) >= 0)
            continue;
        int at = snprintf(error, size, "anisofem.soft: actuator '%s' names no control of %s "
                          "(an actuator of the plugin is named as the control it sets; its "
                          "controls:", mj_id2name(m, mjOBJ_ACTUATOR, a) ?
                          mj_id2name(m, mjOBJ_ACTUATOR, a) : "",
                          mj_getPluginConfig(m, instance, "file"));
        for (int i = 0; i < af_controls(model) && at > 0 && (size_t)at < size; i++)
            at += snprintf(error + at, size - at, " %s", af_control_name(model, i));
        if (at > 0 && (size_t)at < size)
            snprintf(error + at, size - at, "%s)", af_controls(model) ? "" : " none");
        return 0;
    }
    return 1;
}

/* The controls of the instance's actuators (their ctrl), set for the next steps. */
static int set_controls(const mjModel *m, const mjData *d, int instance, soft *s) {
    int k = af_controls(s->model), any = 0;
    double *values = s->values;
    for (int i = 0; i < k; i++)
        values[i] = af_control_value(s->model, i);
    for (int a = 0; a < m->nu; a++)
        if (m->actuator_plugin[a] == instance) {
            int i = control_of(m, a, s->model);
            any |= values[i] != d->ctrl[a];   /* forming the energy costs r^2 to r^3 */
            values[i] = d->ctrl[a];
        }
    return any ? af_set_controls(s->model, values) : AF_OK;
}

static int by_size(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* "a box of half sizes 0.01 0.015 0.01 m" for a kind (AF_PLANE ...; -1: another) and its n
 * sizes (0: "a box"), into text. */
static void shape_text(int kind, const double *sizes, int n, char *text, size_t size) {
    static const char *kinds[] = {"plane", "sphere", "box", "capsule"};
    static const char *named[] = {"", " of radius", " of half sizes",
                                  " of radius and half length"};
    int at = snprintf(text, size, "a %s%s", kind >= 0 ? kinds[kind] : "shape no obstacle has",
                      kind >= 0 && n ? named[kind] : "");
    for (int k = 0; k < n && at > 0 && (size_t)at < size; k++)
        at += snprintf(text + at, size - at, " %g", sizes[k]);
    if (n && at > 0 && (size_t)at < size)
        snprintf(text + at, size - at, " m");
}

/* Whether geom g has the shape of the model's obstacle i (its kind, and its sizes to 1e-6 of
 * the largest); else 0 with error saying how they differ. */
static int same_shape(const mjModel *m, int g, const af_model *model, int i, const char *file,
                      char *error, size_t size) {
    static const int types[] = {mjGEOM_PLANE, mjGEOM_SPHERE, mjGEOM_BOX, mjGEOM_CAPSULE};
    double G[15], want[3] = {0.0, 0.0, 0.0}, have[3] = {0.0, 0.0, 0.0}, axis[3], largest = 0.0;
    int kind = af_obstacle_shape(model, i, G), type = -1, n = 0, same = 1;
    char theirs[160], ours[160];
    for (int k = 0; k < 4; k++)
        if (m->geom_type[g] == types[k])
            type = k;
    if (kind == AF_SPHERE) {
        want[0] = G[3];
        n = 1;
    } else if (kind == AF_BOX) {
        mju_copy3(want, G + 3);
        n = 3;
    } else if (kind == AF_CAPSULE) {
        mju_sub3(axis, G + 3, G);
        want[0] = G[6];
        want[1] = 0.5 * mju_norm3(axis);
        n = 2;
    }
    mju_copy(have, m->geom_size + 3 * g, n);
    if (kind == AF_BOX) {   /* the axes may be ordered otherwise */
        qsort(want, 3, sizeof(double), by_size);
        qsort(have, 3, sizeof(double), by_size);
    }
    for (int k = 0; k < n; k++)
        largest = mju_max(largest, mju_max(want[k], have[k]));
    for (int k = 0; k < n; k++)
        same &= mju_abs(want[k] - have[k]) <= 1e-6 * largest;
    if (type == kind && same)
        return 1;
    shape_text(kind, want, n, ours, sizeof ours);
    shape_text(type, have, type == kind ? n : 0, theirs, sizeof theirs);
    snprintf(error, size, "anisofem.soft: geom '%s' is named as the obstacle of %s, %s, but is "
             "%s (MJCF sizes are half extents): a geom named as an obstacle must have its "
             "shape", mj_id2name(m, mjOBJ_GEOM, g), file, ours, theirs);
    return 0;
}

/* Whether each geom named as one of the model's obstacles has its shape (same_shape). */
static int obstacles_match(const mjModel *m, int instance, const af_model *model, char *error,
                           size_t size) {
    for (int i = 0; i < af_obstacles(model); i++) {
        int g = mj_name2id(m, mjOBJ_GEOM, af_obstacle_name(model, i));
        if (g >= 0 && !same_shape(m, g, model, i, mj_getPluginConfig(m, instance, "file"),
                                  error, size))
            return 0;
    }
    return 1;
}

/* What is wrong with the instance (its file, its body, its substeps), or "" where nothing. */
static void check(const mjModel *m, int instance, char *error, size_t size) {
    af_model *model = load(m, instance, error, size);
    int b;
    if (!model)
        return;
    b = carrier(m, instance);
    if (b < 0)
        snprintf(error, size, "anisofem.soft: no body carries the instance (add "
                 "<plugin instance=\"...\"/> to a body)");
    else if (af_kind(model) == AF_REDUCED && turns(m, b))
        snprintf(error, size, "anisofem.soft: %s is a reduced model, which moves with its body "
                 "only by translation, on body '%s', which can turn (a joint other than a "
                 "slide, or a mocap body): export it with --framed, or carry it on slide joints",
                 mj_getPluginConfig(m, instance, "file"), mj_id2name(m, mjOBJ_BODY, b));
    else if (substeps(m, instance, error, size) < 0 || timestep(m, instance, error, size) < 0)
        ;
    else if (!controls_named(m, instance, model, error, size))
        ;
    else if (!obstacles_match(m, instance, model, error, size))
        ;
    else if (m->opt.integrator == mjINT_RK4)
        snprintf(error, size, "anisofem.soft: the RK4 integrator computes forces at times "
                 "within a step, where the soft body cannot be stepped back; use Euler, "
                 "implicit or implicitfast");
    else
        error[0] = '\0';
    af_free(model);
}

static int nstate(const mjModel *m, int instance) {
    char error[1024] = "";
    af_model *model;
    int size;
    check(m, instance, error, sizeof error);
    if (error[0]) {
        mju_error("%s", error);
        return 0;
    }
    model = load(m, instance, error, sizeof error);
    size = HEADER + af_state_size(model) + OBSTACLE * af_obstacles(model);
    af_free(model);
    return size;
}

/* The body's pose (3 x 4, [R | p], row-major) in d. */
static void pose(const mjModel *m, const mjData *d, int b, double *base) {
    (void)m;
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++)
            base[4 * i + j] = d->xmat[9 * b + 3 * i + j];
        base[4 * i + 3] = d->xpos[3 * b + i];
    }
}

/* The runtime's base: 3 x 3 rotation then translation (anisofem.h, af_step). */
static void runtime_base(const double *pose34, double *base) {
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++)
            base[3 * i + j] = pose34[4 * i + j];
        base[9 + i] = pose34[4 * i + 3];
    }
}

/* The soft body's vertices (n x 3), m, in the world: a reduced model's file coordinates are
 * its fixed body's. */
static void world_positions(const mjModel *m, const mjData *d, const soft *s,
                            const double *state, double *x) {
    af_positions(s->model, state + HEADER, x);
    if (af_kind(s->model) == AF_REDUCED) {
        double at[12], y[3];
        pose(m, d, s->body, at);
        for (int i = 0; i < s->n; i++) {
            for (int a = 0; a < 3; a++)
                y[a] = at[4 * a] * x[3 * i] + at[4 * a + 1] * x[3 * i + 1]
                       + at[4 * a + 2] * x[3 * i + 2] + at[4 * a + 3];
            mju_copy3(x + 3 * i, y);
        }
    }
}

/* Whether the instance's state in d has been placed where its body is. */
static int state_placed(const mjModel *m, const mjData *d, int instance) {
    return d->plugin_state[m->plugin_stateadr[instance] + AT] != UNPLACED;
}

/* Gravity on the soft body, in the file's coordinates where its carrier is fixed (the body's
 * rotation undone), in the world's where it moves (a framed model's positions are the
 * world's). */
static int set_gravity(const mjModel *m, const mjData *d, soft *s) {
    const double *mass = af_masses(s->model);
    double g[3], base[12], *force = s->scratch;
    mju_copy3(g, m->opt.gravity);
    if (af_kind(s->model) == AF_REDUCED) {
        pose(m, d, s->body, base);
        for (int i = 0; i < 3; i++)
            g[i] = base[i] * m->opt.gravity[0] + base[4 + i] * m->opt.gravity[1]
                   + base[8 + i] * m->opt.gravity[2];
    }
    for (int i = 0; i < s->n; i++)
        for (int k = 0; k < 3; k++)
            force[3 * i + k] = mass[i] * g[k];
    return af_set_constant_force(s->model, force);
}

static int by_pair(const void *a, const void *b) {
    const int *p = a, *q = b;
    return p[0] != q[0] ? (p[0] > q[0]) - (p[0] < q[0]) : (p[1] > q[1]) - (p[1] < q[1]);
}

/* The surface triangles' edges, each once (s->edges, s->nedge); 0 where out of memory. */
static int surface_edges(soft *s) {
    int count, kept = 0;
    const int *tri = af_surface(s->model, &count);
    int *e = malloc(6 * (size_t)count * sizeof(int));
    if (!e)
        return 0;
    for (int t = 0; t < count; t++)
        for (int k = 0; k < 3; k++) {
            int a = tri[3 * t + k], b = tri[3 * t + (k + 1) % 3];
            e[6 * t + 2 * k] = a < b ? a : b;
            e[6 * t + 2 * k + 1] = a < b ? b : a;
        }
    qsort(e, 3 * (size_t)count, 2 * sizeof(int), by_pair);
    for (int i = 0; i < 3 * count; i++)
        if (i == 0 || by_pair(e + 2 * i, e + 2 * (kept - 1)) != 0) {
            e[2 * kept] = e[2 * i];
            e[2 * kept + 1] = e[2 * i + 1];
            kept++;
        }
    s->edges = e;
    s->nedge = kept;
    return 1;
}

static int init(const mjModel *m, mjData *d, int instance) {
    char error[1024] = "";
    int count, obstacles;
    soft *s;
    check(m, instance, error, sizeof error);
    if (error[0]) {
        mju_warning("%s", error);
        return -1;
    }
    count = substeps(m, instance, error, sizeof error);
    s = calloc(1, sizeof *s);
    if (!s)
        return -1;
    s->model = load(m, instance, error, sizeof error);
    if (!s->model) {
        mju_warning("%s", error);
        free(s);
        return -1;
    }
    obstacles = af_obstacles(s->model);
    s->body = carrier(m, instance);
    s->free = moves(m, s->body);
    s->substeps = count;
    s->timestep = timestep(m, instance, error, sizeof error);
    s->n = af_vertices(s->model);
    s->x = calloc(3 * (size_t)s->n, sizeof(double));
    s->v = calloc(3 * (size_t)s->n, sizeof(double));
    s->geom = malloc(((size_t)obstacles + 1) * sizeof(int));
    s->owner = malloc(((size_t)obstacles + 1) * sizeof(int));
    s->from = malloc((FROM * (size_t)obstacles + 1) * sizeof(double));
    s->scratch = malloc(3 * (size_t)s->n * sizeof(double));
    s->values = malloc(((size_t)af_controls(s->model) + 1) * sizeof(double));
    for (int i = 0; s->geom && s->owner && i < obstacles; i++) {
        s->geom[i] = mj_name2id(m, mjOBJ_GEOM, af_obstacle_name(s->model, i));
        s->owner[i] = s->geom[i] >= 0 ? free_body(m, s->geom[i]) : -1;
    }
    d->plugin_data[instance] = (uintptr_t)s;
    if (!s->x || !s->v || !s->geom || !s->owner || !s->from || !s->scratch || !s->values
        || !surface_edges(s)) {
        mju_warning("anisofem.soft: out of memory");
        return -1;
    }
    return 0;
}

static void destroy(mjData *d, int instance) {
    soft *s = (soft *)d->plugin_data[instance];
    if (s) {
        af_free(s->model);
        free(s->x);
        free(s->v);
        free(s->edges);
        free(s->geom);
        free(s->owner);
        free(s->from);
        free(s->scratch);
        free(s->values);
        free(s);
    }
    d->plugin_data[instance] = 0;
}

static void copy(mjData *dest, const mjModel *m, const mjData *src, int instance) {
    const soft *from = (const soft *)src->plugin_data[instance];
    soft *to;
    destroy(dest, instance);
    if (init(m, dest, instance) != 0 || !from)
        return;
    to = (soft *)dest->plugin_data[instance];
    memcpy(to->x, from->x, 3 * (size_t)from->n * sizeof(double));
    memcpy(to->v, from->v, 3 * (size_t)from->n * sizeof(double));
    memcpy(to->from, from->from, FROM * (size_t)af_obstacles(from->model) * sizeof(double));
    mju_copy3(to->placed, from->placed);
    if (state_placed(m, dest, instance))
        set_gravity(m, dest, to);
}

static void reset(const mjModel *m, double *state, void *data, int instance) {
    soft *s = (soft *)data;
    (void)m;
    (void)instance;
    memset(state, 0, HEADER * sizeof(double));
    state[AT] = UNPLACED;
    if (s)
        af_rest_state(s->model, state + HEADER);
}

/* The instance's per-obstacle block (OBSTACLE doubles each) in its plugin state. */
static double *obstacle_state(const soft *s, double *state) {
    return state + HEADER + af_state_size(s->model);
}

/* The soft body at rest where its body is (gravity set for where it is), at d's time. */
static int place(const mjModel *m, mjData *d, soft *s, double *state, const double *base) {
    int code = set_gravity(m, d, s);
    double *blocks = obstacle_state(s, state);
    if (code == AF_OK && af_kind(s->model) == AF_FRAMED)
        code = af_carry_state(s->model, state + HEADER, base);
    if (s->free)
        world_positions(m, d, s, state, s->x);
    memset(s->v, 0, 3 * (size_t)s->n * sizeof(double));
    for (int i = 0; i < af_obstacles(s->model); i++) {
        af_obstacle_position(s->model, i, s->from + FROM * i);
        if (s->geom[i] >= 0) {
            mju_copy3(s->from + FROM * i + 3, d->geom_xpos + 3 * s->geom[i]);
            mju_copy(s->from + FROM * i + 6, d->geom_xmat + 9 * s->geom[i], 9);
        }
        mju_zero(blocks + OBSTACLE * i, OBSTACLE);
        blocks[OBSTACLE * i] = NAN;
    }
    mju_copy3(s->placed, d->xpos + 3 * s->body);
    mju_zero(state + STEP, HEADER - STEP);
    mju_copy3(state + CARRIED, d->xpos + 3 * s->body);
    state[AT] = d->time;
    return code;
}

/* a (3) in the world's axes into the file's: a reduced model's are its body's (the body
 * turns not), a framed model's the world's. */
static void into_file(const soft *s, const double *at, const double *a, double *out) {
    if (af_kind(s->model) == AF_FRAMED) {
        mju_copy3(out, a);
        return;
    }
    for (int k = 0; k < 3; k++)
        out[k] = at[k] * a[0] + at[4 + k] * a[1] + at[8 + k] * a[2];
}

/* The reverse of into_file. */
static void into_world(const soft *s, const double *at, const double *a, double *out) {
    if (af_kind(s->model) == AF_FRAMED) {
        mju_copy3(out, a);
        return;
    }
    for (int k = 0; k < 3; k++)
        out[k] = at[4 * k] * a[0] + at[4 * k + 1] * a[1] + at[4 * k + 2] * a[2];
}

/* A (3 x 3, row-major) in the world's axes into the file's (into_file): R^T A R. */
static void matrix_into_file(const soft *s, const double *at, const double *A, double *out) {
    double R[9], T[9];
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            R[3 * i + j] = af_kind(s->model) == AF_FRAMED ? (i == j) : at[4 * i + j];
    mju_mulMatMat(T, A, R, 3, 3, 3);
    mju_mulMatTMat(out, R, T, 3, 3, 3);
}

/* ximat diag(d) ximat^T of body b (3 x 3): its inertia (d: body_inertia) in the world. */
static void world_inertia(const mjData *d, int b, const double *diag, double *out) {
    const double *X = d->ximat + 9 * b;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++)
            out[3 * i + j] = X[3 * i] * diag[0] * X[3 * j] + X[3 * i + 1] * diag[1]
                             * X[3 * j + 1] + X[3 * i + 2] * diag[2] * X[3 * j + 2];
}

/* Obstacle i's free body b (a geom on it is named as the obstacle): its mass, inertia, center
 * of mass (offset from the geom's center), turn since the soft body was placed, velocity and
 * the acceleration all but the soft body gave it over the last step, relative to the carrier
 * (its velocity and acceleration: carrier, 6), in the file's axes. */
static int free_motion(const mjModel *m, const mjData *d, soft *s, int i, int b,
                       const double *at, const double *carrier, double h, double *block) {
    double velocity[6], push[6], v[6], a[6], I[9], If[9], inverse[3], Iinv[9], offset[3], w[3];
    double Rg[9], turn[9], shape[15];
    int g = s->geom[i];
    mj_objectVelocity(m, d, mjOBJ_BODY, b, velocity, 0);     /* spin, then its COM's */
    world_inertia(d, b, m->body_inertia + 3 * b, I);
    for (int k = 0; k < 3; k++)
        inverse[k] = 1.0 / m->body_inertia[3 * b + k];
    world_inertia(d, b, inverse, Iinv);
    mju_mulMatVec(w, Iinv, block + 9, 3, 3);
    for (int k = 0; k < 3; k++) {
        int first = isnan(block[0]) || !(h > 0.0);
        push[k] = first ? m->opt.gravity[k]
                  : (velocity[3 + k] - block[k]) / h - block[6 + k] / m->body_mass[b];
        push[3 + k] = first ? 0.0 : (velocity[k] - block[3 + k]) / h - w[k];
        block[k] = velocity[3 + k];
        block[3 + k] = velocity[k];
        velocity[3 + k] -= carrier[k];
        push[k] -= carrier[3 + k];
    }
    into_file(s, at, velocity + 3, v);
    into_file(s, at, velocity, v + 3);
    into_file(s, at, push, a);
    into_file(s, at, push + 3, a + 3);
    matrix_into_file(s, at, I, If);
    mju_sub3(w, d->xipos + 3 * b, d->geom_xpos + 3 * g);
    into_file(s, at, w, offset);
    if (af_obstacle_shape(s->model, i, shape) == AF_CAPSULE)   /* its position: its end a */
        for (int k = 0; k < 3; k++)
            offset[k] += 0.5 * (shape[3 + k] - shape[k]);
    mju_mulMatMatT(Rg, d->geom_xmat + 9 * g, s->from + FROM * i + 6, 3, 3, 3);
    matrix_into_file(s, at, Rg, turn);
    if (af_turn_obstacle(s->model, i, turn) != AF_OK)
        return AF_BAD_INPUT;
    return af_obstacle_motion(s->model, i, m->body_mass[b], If, offset, v, a);
}

/* Each obstacle of the file a geom is named for, moved by the geom's translation since the
 * soft body was placed, less its carrier's where that is a reduced model's (whose file
 * coordinates are its body's); a free one also turned as the geom has turned, with its motion
 * (free_motion). */
static int move_obstacles(const mjModel *m, const mjData *d, soft *s, double *state,
                          const double *carrier) {
    double at[12], *blocks = obstacle_state(s, state), h = state[STEP];
    pose(m, d, s->body, at);
    for (int i = 0; i < af_obstacles(s->model); i++) {
        double shift[3], target[3];
        if (s->geom[i] < 0)
            continue;
        for (int k = 0; k < 3; k++)
            shift[k] = d->geom_xpos[3 * s->geom[i] + k] - s->from[FROM * i + 3 + k]
                       - (af_kind(s->model) == AF_REDUCED ? at[4 * k + 3] - s->placed[k] : 0.0);
        into_file(s, at, shift, target);
        for (int k = 0; k < 3; k++)
            target[k] += s->from[FROM * i + k];
        if (af_move_obstacle(s->model, i, target) != AF_OK)
            return AF_BAD_INPUT;
        if (s->owner[i] >= 0 && free_motion(m, d, s, i, s->owner[i], at, carrier, h,
                                             blocks + OBSTACLE * i) != AF_OK)
            return AF_BAD_INPUT;
    }
    return AF_OK;
}

/* The soft body's world positions now into s->x, velocities over the last step (of h s)
 * into s->v; where its carrier moves, the carrier's impulse on it over that step (its
 * momentum's change less gravity's and the obstacles' impulses; linear then angular about
 * the world's origin), over h, into the state's pull. */
static void account(const mjModel *m, mjData *d, soft *s, double *state, double h) {
    const double *mass = af_masses(s->model);
    double *x1 = s->scratch, pull[6], at[12], arm[3], touched[6];
    if (!s->free)
        return;
    pose(m, d, s->body, at);
    world_positions(m, d, s, state, x1);
    into_world(s, at, state + TOUCHED, touched);   /* the obstacles' impulse, in the world */
    into_world(s, at, state + TOUCHED + 3, touched + 3);
    for (int k = 0; k < 3; k++)
        arm[k] = af_kind(s->model) == AF_REDUCED ? at[4 * k + 3] : 0.0;
    mju_cross(pull + 3, arm, touched);      /* what the soft body gave them, given back */
    for (int k = 0; k < 3; k++) {
        pull[k] = touched[k];
        pull[3 + k] += touched[3 + k];
    }
    for (int i = 0; i < s->n; i++) {
        double *x = s->x + 3 * i, *v = s->v + 3 * i, v1[3], g[3], before[3], after[3];
        for (int k = 0; k < 3; k++) {
            v1[k] = (x1[3 * i + k] - x[k]) / h;
            g[k] = mass[i] * m->opt.gravity[k] * h;
        }
        mju_cross(before, x, v);
        mju_cross(after, x1 + 3 * i, v1);
        for (int k = 0; k < 3; k++) {
            pull[k] += mass[i] * (v1[k] - v[k]) - g[k];
            pull[3 + k] += mass[i] * (after[k] - before[k]);
        }
        mju_cross(after, x1 + 3 * i, g);
        for (int k = 0; k < 3; k++) {
            pull[3 + k] -= after[k];
            x[k] = x1[3 * i + k];
            v[k] = v1[k];
        }
    }
    for (int k = 0; k < 6; k++)
        state[PULL + k] = pull[k] / h;
}

/* Steps of h s in all from the state's: the carrier's velocity and acceleration over the
 * last step estimated (a reduced model's step is in its frame, the acceleration an inertial
 * force), the controls and obstacles set, `substeps` backward-Euler steps (to base: a framed
 * model's held vertices there), and the obstacles' impulse and forces kept. */
static int advance(const mjModel *m, mjData *d, int instance, soft *s, double *state,
                   const double *base, double h) {
    const double *mass = af_masses(s->model);
    double at[12], carrier[6], inertial[3], *force = NULL, *blocks = obstacle_state(s, state);
    double last = state[STEP] > 0.0 ? state[STEP] : h;
    int code;
    pose(m, d, s->body, at);
    for (int k = 0; k < 3; k++) {   /* its velocity and acceleration over the last step */
        carrier[k] = (at[4 * k + 3] - state[CARRIED + k]) / last;
        carrier[3 + k] = (carrier[k] - state[CARRIED + 3 + k]) / last;
        state[CARRIED + k] = at[4 * k + 3];
        state[CARRIED + 3 + k] = carrier[k];
    }
    if (af_kind(s->model) == AF_FRAMED)
        mju_zero(carrier, 6);
    code = set_controls(m, d, instance, s);
    if (code == AF_OK)
        code = move_obstacles(m, d, s, state, carrier);
    if (code != AF_OK)
        return code;
    into_file(s, at, carrier + 3, inertial);
    if (inertial[0] != 0.0 || inertial[1] != 0.0 || inertial[2] != 0.0) {
        force = s->scratch;
        for (int i = 0; i < s->n; i++)
            for (int k = 0; k < 3; k++)
                force[3 * i + k] = -mass[i] * inertial[k];
    }
    mju_zero(state + TOUCHED, 6);
    for (int i = 0; i < af_obstacles(s->model); i++)
        mju_zero(blocks + OBSTACLE * i + 6, 6);
    for (int j = 0; j < s->substeps; j++) {
        if ((code = af_step(s->model, state + HEADER, force, base, h / s->substeps)) != AF_OK)
            return code;
        for (int i = 0; i < af_obstacles(s->model); i++) {   /* its impulse, about the origin */
            double wrench[6], center[3], moment[3], *mean = blocks + OBSTACLE * i + 6;
            af_obstacle_wrench(s->model, i, wrench);
            af_obstacle_center(s->model, i, center);
            mju_cross(moment, center, wrench);
            for (int k = 0; k < 3; k++) {
                state[TOUCHED + k] += wrench[k] * h / s->substeps;
                state[TOUCHED + 3 + k] += (moment[k] + wrench[3 + k]) * h / s->substeps;
            }
            for (int k = 0; k < 6; k++)
                mean[k] += wrench[k] / s->substeps;
        }
    }
    for (int i = 0; i < af_obstacles(s->model); i++) {   /* the step's mean wrench on each */
        double mean[6];
        mju_copy(mean, blocks + OBSTACLE * i + 6, 6);
        into_world(s, at, mean, blocks + OBSTACLE * i + 6);
        into_world(s, at, mean + 3, blocks + OBSTACLE * i + 9);
    }
    state[STEP] = h;
    return AF_OK;
}

/* The soft body's pull on its carrier and its force on each free obstacle's body, into the
 * passive forces. */
static void apply(const mjModel *m, mjData *d, const soft *s, const double *state) {
    const double *pull = state + PULL, *blocks = obstacle_state(s, (double *)state);
    double force[3], moment[3], at[3];
    const double *point = d->xipos + 3 * s->body;
    mju_scl3(force, pull, -1.0);
    mju_cross(at, point, force);
    for (int k = 0; k < 3; k++)
        moment[k] = -pull[3 + k] - at[k];
    if (s->free && s->body > 0)
        mj_applyFT(m, d, force, moment, point, s->body, d->qfrc_passive);
    for (int i = 0; i < af_obstacles(s->model); i++) {
        int b = s->owner[i];
        if (b >= 0)
            mj_applyFT(m, d, blocks + OBSTACLE * i + 6, blocks + OBSTACLE * i + 9,
                       d->xipos + 3 * b, b, d->qfrc_passive);
    }
}

static void compute(const mjModel *m, mjData *d, int instance, int capability) {
    soft *s = (soft *)d->plugin_data[instance];
    double *state = d->plugin_state + m->plugin_stateadr[instance];
    double at[12], base[12], h, half = 0.5 * m->opt.timestep;
    int code = AF_OK;
    if (capability & mjPLUGIN_ACTUATOR) {   /* its actuators set controls, push nothing */
        for (int a = 0; a < m->nu; a++)
            if (m->actuator_plugin[a] == instance)
                d->actuator_force[a] = 0.0;
    }
    if (!(capability & mjPLUGIN_PASSIVE) || !s)
        return;
    h = s->timestep > 0.0 ? s->timestep : m->opt.timestep;
    pose(m, d, s->body, at);
    runtime_base(at, base);
    if (state[AT] == UNPLACED) {
        if ((code = place(m, d, s, state, base)) != AF_OK) {
            mju_warning("anisofem.soft: %s", af_error(s->model));
            return;
        }
        if (af_kind(s->model) == AF_FRAMED)
            return;
        state[AT] -= h;      /* a reduced model steps ahead from here at once */
    }
    if (af_kind(s->model) == AF_FRAMED && d->time - state[AT] > h - half) {
        h = d->time - state[AT];              /* to where the body is now */
        code = advance(m, d, instance, s, state, base, h);
        if (code == AF_OK) {
            account(m, d, s, state, h);
            state[AT] = d->time;
        }
    } else if (af_kind(s->model) == AF_REDUCED && d->time > state[AT] - half) {
        if (state[STEP] > 0.0)                 /* the step that ends now */
            account(m, d, s, state, state[STEP]);
        code = advance(m, d, instance, s, state, NULL, h);
        if (code == AF_OK)
            state[AT] = d->time + h;
    }
    if (code != AF_OK) {
        mju_warning("anisofem.soft: at t = %g s: %s", d->time, af_error(s->model));
        return;
    }
    apply(m, d, s, state);
}

/* A right triangle in scn (where it has room): its right angle at f, its legs from f to p
 * and to c (f, p, c: 3 each). */
static void right_triangle(mjvScene *scn, const double *f, const double *p, const double *c,
                           const float *rgba) {
    double x[3], y[3], z[3], size[3] = {0.0, 0.0, 0.0}, mat[9];
    mjvGeom *g;
    mju_sub3(x, p, f);
    mju_sub3(y, c, f);
    size[0] = mju_normalize3(x);
    size[1] = mju_normalize3(y);
    if (size[0] < mjMINVAL || size[1] < mjMINVAL || scn->ngeom >= scn->maxgeom)
        return;
    mju_cross(z, x, y);
    for (int i = 0; i < 3; i++) {   /* the frame's columns: x, y, z */
        mat[3 * i] = x[i];
        mat[3 * i + 1] = y[i];
        mat[3 * i + 2] = z[i];
    }
    g = scn->geoms + scn->ngeom++;
    mjv_initGeom(g, mjGEOM_TRIANGLE, size, f, mat, rgba);
    g->category = mjCAT_DECOR;
}

/* The soft body's surface in MuJoCo's scene (as far as it has room), as MuJoCo draws a flex:
 * its faces with the flex skin or face switch (each triangle two right triangles, split at
 * the foot of the height on its longest side: MuJoCo's triangle geom is a right one), its
 * edges as lines with the flex edge switch. */
static void visualize(const mjModel *m, mjData *d, const mjvOption *opt, mjvScene *scn,
                      int instance) {
    soft *s = (soft *)d->plugin_data[instance];
    const double *state = d->plugin_state + m->plugin_stateadr[instance];
    static const float face[4] = {0.45f, 0.65f, 0.9f, 1.0f}, edge[4] = {0.1f, 0.2f, 0.4f, 1.0f};
    double *x;
    int count;
    const int *tri;
    if (!s)
        return;
    world_positions(m, d, s, state, x = s->scratch);
    tri = af_surface(s->model, &count);
    for (int t = 0; (opt->flags[mjVIS_FLEXSKIN] || opt->flags[mjVIS_FLEXFACE]) && t < count;
         t++) {
        double side[3], foot[3], *a, *b, *c, longest = -1.0, along, length;
        int k = 0;
        for (int j = 0; j < 3; j++) {          /* the longest side a-b, c across it */
            mju_sub3(side, x + 3 * tri[3 * t + (j + 1) % 3], x + 3 * tri[3 * t + j]);
            if (mju_dot3(side, side) > longest) {
                longest = mju_dot3(side, side);
                k = j;
            }
        }
        a = x + 3 * tri[3 * t + k];
        b = x + 3 * tri[3 * t + (k + 1) % 3];
        c = x + 3 * tri[3 * t + (k + 2) % 3];
        mju_sub3(side, b, a);
        length = mju_dot3(side, side);
        mju_sub3(foot, c, a);
        along = length > 0.0 ? mju_dot3(foot, side) / length : 0.0;
        mju_addScl3(foot, a, side, along);
        right_triangle(scn, foot, b, c, face);  /* counter-clockwise, as the surface's */
        right_triangle(scn, foot, c, a, face);
    }
    for (int e = 0; opt->flags[mjVIS_FLEXEDGE] && e < s->nedge && scn->ngeom < scn->maxgeom;
         e++) {
        mjvGeom *g = scn->geoms + scn->ngeom++;
        mjv_initGeom(g, mjGEOM_NONE, NULL, NULL, NULL, edge);
        mjv_connector(g, mjGEOM_LINE, 1.0, x + 3 * s->edges[2 * e],
                      x + 3 * s->edges[2 * e + 1]);
        g->category = mjCAT_DECOR;
    }
}

mjPLUGIN_LIB_INIT(anisofem_soft) {
    mjpPlugin plugin;
    mjp_defaultPlugin(&plugin);
    plugin.name = "anisofem.soft";
    plugin.capabilityflags = mjPLUGIN_PASSIVE | mjPLUGIN_ACTUATOR;
    plugin.nattribute = sizeof attributes / sizeof attributes[0];
    plugin.attributes = attributes;
    plugin.nstate = nstate;
    plugin.init = init;
    plugin.destroy = destroy;
    plugin.copy = copy;
    plugin.reset = reset;
    plugin.compute = compute;
    plugin.visualize = visualize;
    mjp_registerPlugin(&plugin);
}
