/* anisofem's runtime: a reduced model or a framed model of one asset, written by `python -m
 * export reduced [--framed]` (PATH.json + PATH.bin), stepped by backward Euler in C99 with no
 * dependency beyond the C library. One API for both kinds of model; it builds as C99 or C++.
 *
 *   char err[512];
 *   af_model *m = af_load("tentacle", NULL, err, sizeof err);   // NULL: err says why
 *   int n = af_vertices(m), size = af_state_size(m);
 *   double *state = malloc(size * sizeof(double)), *x = malloc(3 * n * sizeof(double));
 *   af_rest_state(m, state);
 *   af_set_constant_force(m, gravity);                   // n x 3, N: projected once
 *   if (af_step(m, state, drag, NULL, 0.02) != AF_OK)    // drag: n x 3 N, or NULL
 *       puts(af_error(m));
 *   af_positions(m, state, x);                           // x: n x 3, m
 *   af_free(m);
 *
 * Units SI: positions m, forces N, time s. Arrays are row-major, vertex by vertex (x0 y0 z0 x1
 * ...). A state is af_state_size doubles that the caller keeps and passes back: for a reduced
 * model its coordinates q and their velocities, for a framed model its state now and a step
 * earlier. A function that can fail returns a negative AF_* code (or NULL) and says why: the
 * loaders in their error buffer, the others in af_error.
 */
#ifndef ANISOFEM_H
#define ANISOFEM_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#if defined(_WIN32)
#define AF_API __declspec(dllexport)
#else
#define AF_API __attribute__((visibility("default")))
#endif

enum {
    AF_OK = 0,
    AF_BAD_FILE = -1,      /* the file is missing, corrupt, or of another format version */
    AF_BAD_INPUT = -2,     /* a non-finite force or state, dt <= 0, a base that is not rigid */
    AF_NOT_CONVERGED = -3, /* Newton stopped short of its tolerance (the state is unchanged) */
    AF_NO_MEMORY = -4,
    AF_OUT_OF_REACH = 1    /* af_reach: the target is out of reach; the nearest point found */
};

/* The kinds of model (af_kind). */
enum { AF_REDUCED = 1, AF_FRAMED = 2 };

/* The kinds of obstacle (af_obstacle_shape). */
enum { AF_PLANE = 0, AF_SPHERE = 1, AF_BOX = 2, AF_CAPSULE = 3 };

typedef struct af_model af_model;

/* Load PATH.json and the .bin its header names, beside it (path without extension; '/' or
 * '\\' separate folders). angle: NULL for a file of one model, or the fiber angle to step in
 * a file of several (`python -m export bake-reduced`), as its header writes it ("30").
 * Returns NULL on failure with the reason in error (error_size bytes; may be 0). */
AF_API af_model *af_load(const char *path, const char *angle, char *error, size_t error_size);
/* The same from memory: the header's JSON text (header_size bytes, no terminator needed) and
 * the .bin's bytes; neither is kept. For engines that pack their assets, and the browser. */
AF_API af_model *af_load_memory(const char *header, size_t header_size, const void *bin,
                                size_t bin_size, const char *angle, char *error,
                                size_t error_size);
AF_API void af_free(af_model *model);

AF_API int af_kind(const af_model *model);
/* n, the vertices the model moves (a display mesh's, where the file was written for one). */
AF_API int af_vertices(const af_model *model);
/* Doubles in a state. */
AF_API int af_state_size(const af_model *model);
/* The rest state: no displacement, no velocity. */
AF_API void af_rest_state(const af_model *model, double *state);

/* A force (n x 3, N) added to every later step (gravity: masses times g), projected once here
 * so that a step need not project it again. NULL clears it. AF_OK or AF_BAD_INPUT. */
AF_API int af_set_constant_force(af_model *model, const double *force);
/* Newton's tolerance (relative: of the reduced gradient over the step's force size for a
 * reduced model, of the largest move over the body's size for a framed one; default 1e-8)
 * and its iteration budget (default 50; 500 for a model with obstacles, whose steps can
 * crawl where many nodes touch at once). AF_OK or AF_BAD_INPUT. */
AF_API int af_set_solver(af_model *model, double tolerance, int max_iter);

/* One backward-Euler step of dt s of state, in place, under the constant force plus nodal
 * forces force (n x 3, N; NULL: none). base: where the held vertices are at the step's end, 12
 * doubles, a rotation R_g (row-major) and a translation c_g, x = R_g x0 + c_g (the hand that
 * holds a finger, the character a tail hangs from); NULL keeps them where they are. Only a
 * framed model's held vertices move. Returns AF_OK, or a negative code with state unchanged
 * and af_error saying why. */
AF_API int af_step(af_model *model, double *state, const double *force, const double *base,
                   double dt);
/* state moved rigidly by base (12 doubles, as af_step's): a framed model's frames and held
 * vertices carried there with no change of shape or speed (a body placed where its carrier
 * starts). A reduced model's held vertices stay where the file has them: AF_OK for the
 * identity, else AF_BAD_INPUT; AF_BAD_INPUT for a base that is not rigid. */
AF_API int af_carry_state(af_model *model, double *state, const double *base);
/* The model's controls, named inputs a controller sets every step: pressures in cavities (Pa)
 * and fiber activations (in [0, 1): the fibers' rest stretch is 1 - a). Their number (0 for
 * a model without, and a framed model), the name of control i (NULL out of range) and its
 * value now (the file's until set). */
AF_API int af_controls(const af_model *model);
AF_API const char *af_control_name(const af_model *model, int i);
AF_API double af_control_value(const af_model *model, int i);
/* The controls' values (af_controls doubles, in their order) for every later step until set
 * again; forming the energy's coefficients costs about r^2 per control and r^3 per pressure.
 * AF_OK, or AF_BAD_INPUT with the controls unchanged and af_error naming the control whose
 * value is not finite, or is an activation outside [0, 1). */
AF_API int af_set_controls(af_model *model, const double *values);
/* Inverse statics: the controls within [low, high] (af_controls doubles each) that bring an
 * effector, the point sum_i weights[i] x[nodes[i]] over count nodes (a vertex: one node of
 * weight 1; a material point: its tet's nodes and shape functions there; a region's mean), to
 * target (3 doubles, m) at static equilibrium under the constant force. From the controls now
 * (clipped to the bounds), their equilibrium's Newton from the last reach's where the controls
 * now are the ones it found (a control loop that sets each answer by af_set_controls), else
 * from rest; where that ends short, again from the bounds' middle; the nearer is kept.
 * tolerance: the distance counted as reached, m (<= 0: 1e-4 of the body's size). Writes the
 * controls found into controls and the effector there into position (3); leaves the model's
 * controls as they were (af_set_controls applies the answer). Returns AF_OK (reached),
 * AF_OUT_OF_REACH (the nearest point found; af_error says how far), or a negative code naming
 * the bad input in af_error. */
AF_API int af_reach(af_model *model, const int *nodes, const double *weights, int count,
                    const double *target, const double *low, const double *high,
                    double tolerance, double *controls, double *position);
/* Rigid obstacles a reduced model's surface cannot pass (a plane, sphere, box or capsule, as
 * the file was written; barrier and friction in every step): their number (0 without
 * contact, and for a framed model), the name of obstacle i (NULL out of range), where it is
 * (3 doubles: a plane's point, a sphere's or box's center, a capsule's end a). af_move_obstacle
 * sets where obstacle i is to be (a translation): the next step moves it there as far as the
 * body lets it (every node kept at a tenth of its gap), the rest of the way at later steps.
 * AF_BAD_INPUT for an index out of range or a position that is not finite. */
AF_API int af_obstacles(const af_model *model);
AF_API const char *af_obstacle_name(const af_model *model, int i);
AF_API int af_obstacle_position(const af_model *model, int i, double *position);
/* Obstacle i's kind (AF_PLANE, AF_SPHERE, AF_BOX or AF_CAPSULE; AF_BAD_INPUT out of range)
 * and where it is now, 15 doubles, m: a plane's point and unit normal; a sphere's center and
 * radius; a box's center, half extents and rotation (row-major, its axes the columns); a
 * capsule's ends a and b and radius; the rest zeros. */
AF_API int af_obstacle_shape(const af_model *model, int i, double *geometry);
AF_API int af_move_obstacle(af_model *model, int i, const double *position);
/* Obstacle i as a free body of `mass` kg (a box the body picks up; 0: moved only by
 * af_move_obstacle, the default): each later step solves its move, and its turn where inertia
 * is given, with the body's, from its velocity and under the acceleration everything but the
 * body gives it (6 doubles each: its center's, m/s and m/s^2, then its spin's, rad/s and
 * rad/s^2; gravity, its other contacts). Its center (its center of mass) is offset (3, m; NULL:
 * none) from its position (af_obstacle_position) at the next step's start; inertia: 9 doubles,
 * kg m^2, about the center, in the file's axes; NULL: it does not turn. A step sets its
 * velocity to the step's; call again to set them (an engine that moves it: every step).
 * AF_BAD_INPUT for an index out of range, a mass < 0, an inertia not symmetric with a positive
 * diagonal, or a number that is not finite. */
AF_API int af_obstacle_motion(af_model *model, int i, double mass, const double *inertia,
                              const double *offset, const double *velocity,
                              const double *acceleration);
/* Obstacle i to be turned by rotation (9 doubles, row-major) from how the file has it, about
 * its position: the next step turns it there where no surface node then comes within a tenth
 * of its gap (else a later step does, the next af_turn_obstacle's turn). AF_BAD_INPUT for a
 * matrix that is not a rotation. */
AF_API int af_turn_obstacle(af_model *model, int i, const double *rotation);
/* The force the body put on obstacle i at the last step's end (3, N) and its moment about the
 * obstacle's center (3, N m; af_obstacle_center): barrier and friction; what an engine applies
 * to the body the obstacle stands for (for a free obstacle that turns, the moment that turns
 * it as the step did: J_l(theta)^T M, J_l the left Jacobian of the step's turn theta; it
 * differs from the forces' moment M by a term of the order of theta). Its center: its position offset by af_obstacle_motion's
 * offset (its center of mass), moved and turned with it since (3, m). */
AF_API int af_obstacle_center(const af_model *model, int i, double *center);
AF_API int af_obstacle_wrench(const af_model *model, int i, double *wrench);
AF_API int af_iterations(const af_model *model);
/* Why the last af_step or af_set_* failed, "" if it did not. */
AF_API const char *af_error(const af_model *model);

/* Positions x (n x 3), m, of a state. */
AF_API void af_positions(const af_model *model, const double *state, double *x);

/* The file's body, to draw it and to form forces: lumped masses (n,), kg; rest positions
 * (n x 3), m; held (n x 3), 1 where a component is held; the boundary triangles (count x 3,
 * counter-clockwise seen from outside) and the tets (count x nodes: 4 or 10); gravity (3,),
 * m/s^2, where the file states one (returns 1, else 0); the time step it was validated at, s
 * (0 where it states none). */
AF_API const double *af_masses(const af_model *model);
AF_API const double *af_rest_positions(const af_model *model);
AF_API const unsigned char *af_held(const af_model *model);
AF_API const int *af_surface(const af_model *model, int *count);
AF_API const int *af_tets(const af_model *model, int *count, int *nodes);
AF_API int af_gravity(const af_model *model, double *g);
AF_API double af_time_step(const af_model *model);

#ifdef __cplusplus
}
#endif

#endif
