/* af_model: one API over the two kinds of model. Loading checks the header (complete JSON, the
 * arrays format, the model format and its version, the angle) and the body's arrays (rest
 * positions, masses, held flags, surface, tets) before the kind reads its own; a step checks
 * its inputs and says why it failed. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "af_internal.h"

/* Newton's default iteration budget, with obstacles as the library's reduced model's. */
#define MAX_ITER 50
#define CONTACT_MAX_ITER 500

#define ERROR_SIZE 320

struct af_model {
    int kind, n, iterations, max_iter, surface_count, tet_count, tet_nodes, has_gravity;
    double tolerance, gravity[3], dt;
    double *rest, *masses, *next;       /* next: a framed step's result before it is kept */
    unsigned char *held;
    int *surface, *tets;
    char *control_names;                /* the controls' names, each ended by a NUL */
    int controls, warm;                 /* warm: reach_q holds the last reach's equilibrium, */
    double *reach_q, *reach_u;          /* at the controls reach_u it found */
    af_reduced *reduced;
    af_framed *framed;
    char error[ERROR_SIZE];
};

void af_free(af_model *m) {
    if (!m) return;
    af_reduced_close(m->reduced);
    af_framed_close(m->framed);
    free(m->rest); free(m->masses); free(m->next); free(m->held); free(m->surface);
    free(m->tets); free(m->control_names); free(m->reach_q); free(m->reach_u);
    free(m);
}

/* The header's model format as a kind, or 0 with a message. */
static int kind_of(const af_file *f) {
    char text[128];
    const char *v = af_top_value(f->json, "format");
    if (!v) {
        af_say(f->error, f->error_size, "%s: no \"format\" key: not an arrays header (python -m "
               "export reduced writes one)", f->name);
        return 0;
    }
    if (!af_string_value(v, text, sizeof text) || strcmp(text, AF_ARRAYS_FORMAT) != 0) {
        af_say(f->error, f->error_size, "%s: format '%s', expected '%s'", f->name, text,
               AF_ARRAYS_FORMAT);
        return 0;
    }
    v = af_top_value(f->json, "model_format");
    if (!v) {
        af_say(f->error, f->error_size, "%s: no \"model_format\" key: the arrays of no model "
               "(python -m export reduced writes one)", f->name);
        return 0;
    }
    af_string_value(v, text, sizeof text);
    if (!strcmp(text, AF_REDUCED_FORMAT)) return AF_REDUCED;
    if (!strcmp(text, AF_FRAMED_FORMAT)) return AF_FRAMED;
    af_say(f->error, f->error_size, "%s: holds model_format '%s', and this runtime reads '%s' and "
           "'%s'; rebuild the file with this version's python -m export reduced [--framed]",
           f->name, text, AF_REDUCED_FORMAT, AF_FRAMED_FORMAT);
    return 0;
}

/* The angle's tag into f->tag, checking that the file holds a model at it; 0 with a message. */
static int pick_angle(af_file *f, const char *angle, const char *probe) {
    const char *angles = af_top_value(f->json, "fiber_angles");
    char list[96];
    f->tag[0] = '\0';
    list[0] = '\0';
    if (angles && *angles == '[') {
        const char *end = strchr(angles, ']');
        snprintf(list, sizeof list, "%.*s", end ? (int)(end - angles + 1) : 0, angles);
    }
    if (angle) {
        if (strlen(angle) > 40) {
            af_say(f->error, f->error_size, "angle: longer than a fiber angle");
            return 0;
        }
        snprintf(f->tag, sizeof f->tag, "@%s", angle);
    }
    if (af_has_array(f, probe, 1)) return 1;
    if (angle)
        af_say(f->error, f->error_size, "angle: %s holds no model at fiber angle %s%s%s",
               f->name, angle, list[0] ? "; its angles: " : "", list);
    else if (list[0])
        af_say(f->error, f->error_size, "angle: %s holds a model per fiber angle %s: name one",
               f->name, list);
    else
        af_say(f->error, f->error_size, "%s: no array %s in its arrays table", f->name, probe);
    return 0;
}

/* The body's arrays every file has, checked against each other and the header's n. */
static int read_body(af_model *m, const af_file *f) {
    long shape[4], i;
    const char *v;
    if (!(m->rest = (double *)af_array(f, "rest_positions", 0, "float64", 2, shape))) return 0;
    m->n = (int)shape[0];
    if (shape[1] != 3) {
        af_say(f->error, f->error_size, "%s: array rest_positions has %ld columns, expected 3",
               f->name, shape[1]);
        return 0;
    }
    v = af_top_value(f->json, "n");
    if (v && strtol(v, NULL, 10) != m->n) {
        af_say(f->error, f->error_size, "%s: the header says n = %ld vertices, and array "
               "rest_positions has %d", f->name, strtol(v, NULL, 10), m->n);
        return 0;
    }
    if (!(m->masses = (double *)af_array(f, "masses", 0, "float64", 1, shape))) return 0;
    if (shape[0] != m->n) goto rows;
    if (!(m->held = (unsigned char *)af_array(f, "held", 0, "uint8", 2, shape))) return 0;
    if (shape[0] != m->n || shape[1] != 3) goto rows;
    if (!(m->surface = (int *)af_array(f, "surface", 0, "int32", 2, shape))) return 0;
    m->surface_count = (int)shape[0];
    if (shape[1] != 3) goto rows;
    for (i = 0; i < 3L * m->surface_count; i++)
        if (m->surface[i] < 0 || m->surface[i] >= m->n) goto index;
    if (!(m->tets = (int *)af_array(f, "tets", 0, "int32", 2, shape))) return 0;
    m->tet_count = (int)shape[0];
    m->tet_nodes = (int)shape[1];
    if (m->tet_nodes != 4 && m->tet_nodes != 10) goto rows;
    for (i = 0; i < (long)m->tet_count * m->tet_nodes; i++)
        if (m->tets[i] < 0 || m->tets[i] >= m->n) goto index;
    for (i = 0; i < m->n; i++)
        if (!(m->masses[i] > 0.0)) {
            af_say(f->error, f->error_size, "%s: array masses holds %g kg at vertex %ld, not a "
                   "positive mass", f->name, m->masses[i], i);
            return 0;
        }
    v = af_top_value(f->json, "gravity");
    if (v && *v == '[') {
        char *next;
        for (i = 0, v++; i < 3; i++) {
            m->gravity[i] = strtod(v, &next);
            if (next == v) break;
            for (v = next; *v == ',' || *v == ' '; v++) continue;
        }
        m->has_gravity = i == 3 && isfinite(m->gravity[0] + m->gravity[1] + m->gravity[2]);
    }
    v = af_top_value(f->json, "dt");
    m->dt = v ? strtod(v, NULL) : 0.0;
    if (!(m->dt > 0.0) || !isfinite(m->dt)) m->dt = 0.0;
    return 1;
rows:
    af_say(f->error, f->error_size, "%s: the arrays masses (n,), held (n, 3), surface (k, 3) and "
           "tets (m, 4 or 10) do not fit rest_positions' %d vertices", f->name, m->n);
    return 0;
index:
    af_say(f->error, f->error_size, "%s: the array surface or tets names a vertex outside the "
           "%d of rest_positions", f->name, m->n);
    return 0;
}

/* The header's controls (a list of names), as many as the model's control arrays hold. */
static int read_control_names(af_model *m, const af_file *f) {
    const char *v = af_top_value(f->json, "controls");
    m->controls = af_reduced_controls(m->reduced);
    if (!v && !m->controls) return 1;
    m->control_names = af_string_list(v, &m->controls);
    if (!m->control_names || m->controls != af_reduced_controls(m->reduced)) {
        af_say(f->error, f->error_size, "%s: the header's \"controls\" is not a list of %d "
               "names, one per entry of array control_kinds", f->name,
               af_reduced_controls(m->reduced));
        return 0;
    }
    return 1;
}

af_model *af_load_named(const char *header, size_t header_size, const void *bin,
                            size_t bin_size, const char *angle, const char *name, char *error,
                            size_t error_size) {
    af_file f;
    af_model *m;
    char *json;
    if (error && error_size) error[0] = '\0';
    json = (char *)malloc(header_size + 1);
    m = (af_model *)calloc(1, sizeof *m);
    if (!json || !m) {
        free(json);
        free(m);
        af_say(error, error_size, "no memory for a model");
        return NULL;
    }
    memcpy(json, header, header_size);
    json[header_size] = '\0';
    memset(&f, 0, sizeof f);
    f.json = json;
    f.bin = (const char *)bin;
    f.bin_size = (long)bin_size;
    f.name = name;
    f.error = error;
    f.error_size = error_size;
    if (strlen(json) != header_size || !af_complete_json(json)) {
        af_say(error, error_size, "%s: not complete JSON (a truncated or binary file?)", f.name);
        goto fail;
    }
    if (!(m->kind = kind_of(&f))) goto fail;
    f.table = af_top_value(json, "arrays");
    if (!f.table || *f.table != '{') {
        af_say(error, error_size, "%s: no \"arrays\" table", f.name);
        goto fail;
    }
    if (!bin) {
        af_say(error, error_size, "%s: no \"bin\" key naming its .bin file", f.name);
        goto fail;
    }
    if (!pick_angle(&f, angle, m->kind == AF_REDUCED ? "W4" : "r")) goto fail;
    if (!read_body(m, &f)) goto fail;
    if (m->kind == AF_REDUCED) {
        if (!(m->reduced = af_reduced_open(&f, m->n, m->rest))) goto fail;
        if (!read_control_names(m, &f)) goto fail;
    } else {
        if (!(m->framed = af_framed_open(&f, m->n, m->rest, m->masses))) goto fail;
        if (!(m->next = (double *)malloc((size_t)af_framed_size(m->framed) * sizeof(double)))) {
            af_say(error, error_size, "no memory for a model");
            goto fail;
        }
    }
    m->tolerance = 1e-8;
    m->max_iter = af_obstacles(m) ? CONTACT_MAX_ITER : MAX_ITER;
    free(json);
    return m;
fail:
    free(json);
    af_free(m);
    return NULL;
}

af_model *af_load_memory(const char *header, size_t header_size, const void *bin,
                         size_t bin_size, const char *angle, char *error, size_t error_size) {
    if (!header || !bin) {
        af_say(error, error_size, "%s: NULL", header ? "bin" : "header");
        return NULL;
    }
    return af_load_named(header, header_size, bin, bin_size, angle, "the header", error,
                         error_size);
}

int af_kind(const af_model *m) { return m->kind; }
int af_vertices(const af_model *m) { return m->n; }
int af_iterations(const af_model *m) { return m->iterations; }
const char *af_error(const af_model *m) { return m->error; }
const double *af_masses(const af_model *m) { return m->masses; }
const double *af_rest_positions(const af_model *m) { return m->rest; }
const unsigned char *af_held(const af_model *m) { return m->held; }
double af_time_step(const af_model *m) { return m->dt; }

int af_state_size(const af_model *m) {
    return m->kind == AF_REDUCED ? 2 * af_reduced_size(m->reduced)
                                 : 2 * af_framed_size(m->framed);
}

void af_rest_state(const af_model *m, double *state) {
    int i, size = af_state_size(m);
    if (m->kind == AF_REDUCED) {
        for (i = 0; i < size; i++) state[i] = 0.0;
    } else {
        af_framed_rest(m->framed, state);
        memcpy(state + size / 2, state, (size_t)(size / 2) * sizeof(double));
    }
}

int af_carry_state(af_model *m, double *state, const double *base) {
    int i, half = af_state_size(m) / 2;
    m->error[0] = '\0';
    if (!base || !af_rigid(base)) {
        af_say(m->error, ERROR_SIZE, "base: not a rigid motion (its first 9 numbers must be a "
               "rotation, row-major, to 1e-9; then a translation)");
        return AF_BAD_INPUT;
    }
    if (m->kind == AF_REDUCED) {
        for (i = 0; i < 12; i++)
            if (base[i] != (i == 0 || i == 4 || i == 8 ? 1.0 : 0.0)) {
                af_say(m->error, ERROR_SIZE, "base: a reduced model holds its vertices where "
                       "the file has them; only a framed model is carried");
                return AF_BAD_INPUT;
            }
        return AF_OK;
    }
    af_framed_carry(m->framed, state, base);
    af_framed_carry(m->framed, state + half, base);
    return AF_OK;
}

const int *af_surface(const af_model *m, int *count) {
    if (count) *count = m->surface_count;
    return m->surface;
}

const int *af_tets(const af_model *m, int *count, int *nodes) {
    if (count) *count = m->tet_count;
    if (nodes) *nodes = m->tet_nodes;
    return m->tets;
}

int af_gravity(const af_model *m, double *g) {
    if (m->has_gravity && g) memcpy(g, m->gravity, sizeof m->gravity);
    return m->has_gravity;
}

/* Whether force (n x 3) is finite, saying where it is not. */
static int finite_force(af_model *m, const double *force, const char *what) {
    long i;
    if (!force) return 1;
    for (i = 0; i < 3L * m->n; i++)
        if (!isfinite(force[i])) {
            af_say(m->error, ERROR_SIZE, "%s: vertex %ld, component %ld is not finite", what,
                   i / 3, i % 3);
            return 0;
        }
    return 1;
}

int af_set_constant_force(af_model *m, const double *force) {
    m->error[0] = '\0';
    if (!finite_force(m, force, "constant force")) return AF_BAD_INPUT;
    return m->kind == AF_REDUCED ? af_reduced_set_force(m->reduced, force)
                                 : af_framed_set_force(m->framed, force);
}

int af_set_solver(af_model *m, double tolerance, int max_iter) {
    m->error[0] = '\0';
    if (!(tolerance >= 0.0) || !isfinite(tolerance) || max_iter < 1) {
        af_say(m->error, ERROR_SIZE, "solver: a tolerance >= 0 and at least 1 iteration, got "
               "%g and %d", tolerance, max_iter);
        return AF_BAD_INPUT;
    }
    m->tolerance = tolerance;
    m->max_iter = max_iter;
    return AF_OK;
}

int af_step(af_model *m, double *state, const double *force, const double *base, double dt) {
    int i, size = af_state_size(m), result;
    m->error[0] = '\0';
    if (!(dt > 0.0) || !isfinite(dt)) {
        af_say(m->error, ERROR_SIZE, "dt: a positive time step, got %g s", dt);
        return AF_BAD_INPUT;
    }
    if (!finite_force(m, force, "force")) return AF_BAD_INPUT;
    for (i = 0; i < size; i++)
        if (!isfinite(state[i])) {
            af_say(m->error, ERROR_SIZE, "state: entry %d is not finite", i);
            return AF_BAD_INPUT;
        }
    if (m->kind == AF_REDUCED) {
        if (base) {
            af_say(m->error, ERROR_SIZE, "base: a reduced model's held vertices stay where they "
                   "are; a framed model's move (python -m export reduced --framed)");
            return AF_BAD_INPUT;
        }
        result = af_reduced_advance(m->reduced, state, state + size / 2, force, dt, m->tolerance,
                                    m->max_iter, m->error, ERROR_SIZE);
        if (result < 0) return result;
    } else {
        for (i = 0; base && i < 12; i++)
            if (!isfinite(base[i])) {
                af_say(m->error, ERROR_SIZE, "base: entry %d is not finite", i);
                return AF_BAD_INPUT;
            }
        result = af_framed_advance(m->framed, state, state + size / 2, m->next, force, base, dt,
                                   m->tolerance, m->max_iter, m->error, ERROR_SIZE);
        if (result < 0) return result;
        memcpy(state + size / 2, state, (size_t)(size / 2) * sizeof(double));
        memcpy(state, m->next, (size_t)(size / 2) * sizeof(double));
    }
    m->iterations = result;
    return AF_OK;
}

int af_controls(const af_model *m) { return m->controls; }

const char *af_control_name(const af_model *m, int i) {
    const char *name = m->control_names;
    if (i < 0 || i >= m->controls) return NULL;
    while (i--) name += strlen(name) + 1;
    return name;
}

double af_control_value(const af_model *m, int i) {
    return i >= 0 && i < m->controls ? af_reduced_control(m->reduced, i) : NAN;
}

int af_set_controls(af_model *m, const double *values) {
    m->error[0] = '\0';
    if (!m->controls) return AF_OK;
    if (!values) {
        af_say(m->error, ERROR_SIZE, "controls: NULL; give %d values", m->controls);
        return AF_BAD_INPUT;
    }
    return af_reduced_set_controls(m->reduced, values, m->control_names, m->error, ERROR_SIZE);
}

int af_obstacles(const af_model *m) {
    return m->kind == AF_REDUCED ? af_contact_count(af_reduced_contact(m->reduced)) : 0;
}

const char *af_obstacle_name(const af_model *m, int i) {
    if (i < 0 || i >= af_obstacles(m)) return NULL;
    return af_contact_name(af_reduced_contact(m->reduced), i);
}

int af_obstacle_position(const af_model *m, int i, double *position) {
    if (i < 0 || i >= af_obstacles(m) || !position) return AF_BAD_INPUT;
    af_contact_position(af_reduced_contact(m->reduced), i, position);
    return AF_OK;
}

int af_obstacle_shape(const af_model *m, int i, double *geometry) {
    if (i < 0 || i >= af_obstacles(m) || !geometry) return AF_BAD_INPUT;
    return af_contact_shape(af_reduced_contact(m->reduced), i, geometry);
}

/* Whether i is one of the model's obstacles; else 0 with af_error saying so (cleared). */
static int is_obstacle(af_model *m, int i) {
    m->error[0] = '\0';
    if (i >= 0 && i < af_obstacles(m)) return 1;
    af_say(m->error, ERROR_SIZE, "obstacle: %d is not one of the model's %d", i,
           af_obstacles(m));
    return 0;
}

int af_move_obstacle(af_model *m, int i, const double *position) {
    int a;
    if (!is_obstacle(m, i)) return AF_BAD_INPUT;
    for (a = 0; a < 3; a++)
        if (!position || !isfinite(position[a])) {
            af_say(m->error, ERROR_SIZE, "obstacle '%s': its position must be 3 finite numbers",
                   af_obstacle_name(m, i));
            return AF_BAD_INPUT;
        }
    af_contact_move(af_reduced_contact(m->reduced), i, position);
    return AF_OK;
}

int af_obstacle_motion(af_model *m, int i, double mass, const double *inertia,
                       const double *offset, const double *velocity,
                       const double *acceleration) {
    int a;
    if (!is_obstacle(m, i)) return AF_BAD_INPUT;
    if (!(mass >= 0.0) || !isfinite(mass)) {
        af_say(m->error, ERROR_SIZE, "obstacle '%s': mass must be a finite number >= 0 kg, got "
               "%g", af_obstacle_name(m, i), mass);
        return AF_BAD_INPUT;
    }
    for (a = 0; a < 6; a++)
        if (!velocity || !acceleration || !isfinite(velocity[a]) || !isfinite(acceleration[a])
            || (offset && a < 3 && !isfinite(offset[a]))) {
            af_say(m->error, ERROR_SIZE, "obstacle '%s': its velocity and acceleration must be "
                   "6 finite numbers each, its center's offset 3 or NULL",
                   af_obstacle_name(m, i));
            return AF_BAD_INPUT;
        }
    if (inertia) {
        double trace = inertia[0] + inertia[4] + inertia[8];
        for (a = 0; a < 9; a++)
            if (!isfinite(inertia[a]) || fabs(inertia[a] - inertia[3 * (a % 3) + a / 3])
                                         > 1e-9 * fabs(trace))
                break;
        if (a < 9 || !(inertia[0] > 0.0 && inertia[4] > 0.0 && inertia[8] > 0.0)) {
            af_say(m->error, ERROR_SIZE, "obstacle '%s': inertia must be a symmetric 3 x 3 "
                   "matrix of finite numbers, its diagonal > 0 kg m^2, or NULL",
                   af_obstacle_name(m, i));
            return AF_BAD_INPUT;
        }
    }
    af_contact_motion(af_reduced_contact(m->reduced), i, mass, inertia, offset, velocity,
                      acceleration);
    return AF_OK;
}

int af_turn_obstacle(af_model *m, int i, const double *rotation) {
    double R[12] = {0.0};
    if (!is_obstacle(m, i)) return AF_BAD_INPUT;
    if (rotation) memcpy(R, rotation, 9 * sizeof(double));
    if (!rotation || !af_rigid(R)) {
        af_say(m->error, ERROR_SIZE, "obstacle '%s': the turn must be a rotation (9 numbers, "
               "row-major, orthonormal to 1e-9, determinant 1)", af_obstacle_name(m, i));
        return AF_BAD_INPUT;
    }
    af_contact_turn(af_reduced_contact(m->reduced), i, rotation);
    return AF_OK;
}

int af_obstacle_center(const af_model *m, int i, double *center) {
    if (i < 0 || i >= af_obstacles(m) || !center) return AF_BAD_INPUT;
    af_contact_center(af_reduced_contact(m->reduced), i, center);
    return AF_OK;
}

int af_obstacle_wrench(const af_model *m, int i, double *wrench) {
    if (i < 0 || i >= af_obstacles(m) || !wrench) return AF_BAD_INPUT;
    memcpy(wrench, af_contact_wrench(af_reduced_contact(m->reduced), i), 6 * sizeof(double));
    return AF_OK;
}

/* The default reach tolerance: this share of the rest shape's largest extent. */
#define REACH_TOLERANCE 1e-4
#define REACH_ITERATIONS 50

int af_reach(af_model *m, const int *nodes, const double *weights, int count,
             const double *target, const double *low, const double *high, double tolerance,
             double *controls, double *position) {
    int i, a, result;
    m->error[0] = '\0';
    if (!m->controls) {
        af_say(m->error, ERROR_SIZE, "reach: the model has no controls to set");
        return AF_BAD_INPUT;
    }
    if (count < 1 || !nodes || !weights || !target || !low || !high || !controls ||
        !position) {
        af_say(m->error, ERROR_SIZE, "reach: an effector of at least one node, a target, "
               "bounds and room for the answer, got count %d or a NULL", count);
        return AF_BAD_INPUT;
    }
    for (i = 0; i < count; i++)
        if (nodes[i] < 0 || nodes[i] >= m->n || !isfinite(weights[i])) {
            af_say(m->error, ERROR_SIZE, "reach: effector node %d is %d with weight %g: a "
                   "vertex of the %d and a finite weight expected", i, nodes[i], weights[i],
                   m->n);
            return AF_BAD_INPUT;
        }
    for (a = 0; a < 3; a++)
        if (!isfinite(target[a])) {
            af_say(m->error, ERROR_SIZE, "reach: target component %d is not finite", a);
            return AF_BAD_INPUT;
        }
    for (i = 0; i < m->controls; i++)
        if (!(low[i] < high[i])) {
            af_say(m->error, ERROR_SIZE, "reach: the bounds of '%s' must have low < high, got "
                   "%g and %g", af_control_name(m, i), low[i], high[i]);
            return AF_BAD_INPUT;
        }
    if (af_reduced_check_controls(m->reduced, low, m->control_names, m->error, ERROR_SIZE) ||
        af_reduced_check_controls(m->reduced, high, m->control_names, m->error, ERROR_SIZE))
        return AF_BAD_INPUT;
    if (!(tolerance > 0.0)) {
        double size = 0.0;
        for (a = 0; a < 3; a++) {
            double lo = m->rest[a], hi = m->rest[a];
            for (i = 1; i < m->n; i++) {
                if (m->rest[3 * i + a] < lo) lo = m->rest[3 * i + a];
                if (m->rest[3 * i + a] > hi) hi = m->rest[3 * i + a];
            }
            if (hi - lo > size) size = hi - lo;
        }
        tolerance = REACH_TOLERANCE * size;
    }
    if (!m->reach_q &&
        !(m->reach_q = (double *)calloc((size_t)af_reduced_size(m->reduced), sizeof(double))))
        return AF_NO_MEMORY;
    if (!m->reach_u && !(m->reach_u = (double *)calloc((size_t)m->controls, sizeof(double))))
        return AF_NO_MEMORY;
    for (i = 0; i < m->controls && m->warm; i++)   /* the last answer's q starts a Newton */
        m->warm = af_reduced_control(m->reduced, i) == m->reach_u[i];  /* at its controls */
    result = af_reduced_reach(m->reduced, nodes, weights, count, target, low, high, tolerance,
                              REACH_ITERATIONS, m->reach_q, m->warm, controls, position,
                              &m->iterations, m->error, ERROR_SIZE);
    m->warm = result >= 0;
    if (m->warm) memcpy(m->reach_u, controls, (size_t)m->controls * sizeof(double));
    return result;
}

void af_positions(const af_model *m, const double *state, double *x) {
    if (m->kind == AF_REDUCED) af_reduced_place(m->reduced, state, x);
    else af_framed_place(m->framed, state, x);
}
