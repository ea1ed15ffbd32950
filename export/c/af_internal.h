/* What the runtime's source files share (not for engines: they include anisofem.h). */
#ifndef AF_INTERNAL_H
#define AF_INTERNAL_H

#include <stddef.h>

#include "anisofem.h"

#define AF_ARRAYS_FORMAT "anisognn-arrays-1"
#define AF_REDUCED_FORMAT "anisofem-reduced-1"
#define AF_FRAMED_FORMAT "anisofem-framed-1"
#define AF_ARMIJO 1e-4

/* An arrays file being read: its JSON header (NUL-terminated), the "arrays" table in it, the
 * raw .bin bytes, the angle's tag ("@30" or ""), and where a failure's message goes. */
typedef struct {
    const char *json, *table, *bin;
    long bin_size;
    char tag[64];
    const char *name;          /* the file, as messages name it */
    char *error;
    size_t error_size;
} af_file;

/* printf into error (size bytes; nothing where error is NULL or size 0). */
void af_say(char *error, size_t size, const char *fmt, ...);
/* The text after `"key":` searching from start; NULL if absent. */
const char *af_value_of(const char *start, const char *key);
/* The same for a key of the JSON object json itself, not of one nested in it. */
const char *af_top_value(const char *json, const char *key);
/* A JSON string value (at its opening quote) copied into out; 0 if it is not one. */
int af_string_value(const char *v, char *out, size_t size);
/* A JSON list of strings (at its '['): its strings packed one after another, each ended by a
 * NUL, in a new buffer (the caller frees it), their number in count; NULL if it is not one. */
char *af_string_list(const char *v, int *count);
/* Whether the file has array `name` (with the angle's tag where tagged). */
int af_has_array(const af_file *f, const char *name, int tagged);
/* A new copy of array `name` (+ the angle's tag where tagged) of dtype `type` ("float64",
 * "int32" or "uint8") and rank `dims`, its shape in shape (4 longs); float64 entries checked
 * finite. NULL with a message naming the file and the array. */
void *af_array(const af_file *f, const char *name, int tagged, const char *type, int dims,
               long *shape);

/* Linear algebra on small dense matrices (row-major, r x r). */
double af_dot(const double *a, const double *b, long r);
/* X[a, b] = sum_c T[a, b, c] u_c for the symmetric T whose sorted triples a <= b <= c are A. */
void af_contract(const double *A, const double *u, double *X, long r);
/* p = -H^-1 g by Cholesky, or with H's eigenvalues clamped to floor_share of the largest
 * (mirror: their absolute values), scratch L, V, B (r x r) and lam, t1 (r). */
void af_newton_direction(const double *H, const double *g, double *p, double *L, double *V,
                         double *lam, double *B, double *t1, long r, double floor_share,
                         int mirror);

/* Whether text (NUL-terminated) is one complete JSON value. */
int af_complete_json(const char *text);
/* af_load_memory with `name` for the file in messages; bin NULL: the header names no .bin. */
af_model *af_load_named(const char *header, size_t header_size, const void *bin,
                        size_t bin_size, const char *angle, const char *name, char *error,
                        size_t error_size);

/* The two kinds of model, behind af_model. rest and masses are the model's (af_model owns
 * them); open returns NULL with a message. */
typedef struct af_reduced af_reduced;
af_reduced *af_reduced_open(const af_file *f, int n, const double *rest);
void af_reduced_close(af_reduced *m);
int af_reduced_size(const af_reduced *m);
int af_reduced_set_force(af_reduced *m, const double *force);
int af_reduced_advance(af_reduced *m, double *q, double *w, const double *force, double dt,
                       double rtol, int max_iter, char *error, size_t error_size);
void af_reduced_place(const af_reduced *m, const double *q, double *x);
/* The static equilibrium under the constant force and the controls now, Newton from q (r,)
 * in place: iterations, or AF_NOT_CONVERGED with a message. */
int af_reduced_static(af_reduced *m, double *q, double rtol, int max_iter, char *error,
                      size_t error_size);
/* dq/du (r x k, row-major) at the equilibrium q under the controls now: -H^-1 dg/du. */
void af_reduced_control_slopes(af_reduced *m, const double *q, double *slopes);
void af_reduced_basis_rows(const af_reduced *m, const int *nodes, const double *weights,
                           int count, double *e0, double *E);
/* Inverse statics (reach.c): AF_OK (reached), AF_OUT_OF_REACH, or a negative code; the
 * controls found, the effector's position there and the iterations taken; the model's
 * controls left as they were. The first descent starts from the controls now; q0 (r,):
 * where its first equilibrium's Newton starts where warm (else 0), overwritten by
 * the answer's equilibrium. */
int af_reduced_reach(af_reduced *m, const int *nodes, const double *weights, int count,
                     const double *target, const double *low, const double *high,
                     double tolerance, int max_iter, double *q0,
                     int warm, double *controls, double *position, int *iterations,
                     char *error, size_t error_size);
int af_reduced_controls(const af_reduced *m);
double af_reduced_control(const af_reduced *m, int i);
int af_reduced_check_controls(const af_reduced *m, const double *values, const char *names,
                              char *error, size_t error_size);
int af_reduced_set_controls(af_reduced *m, const double *values, const char *names, char *error,
                            size_t error_size);

/* A reduced model's contact with rigid obstacles (contact.c): NULL where the file has none
 * (failed 0), or NULL with a message where its arrays are wrong (failed 1). */
typedef struct af_contact af_contact;
af_contact *af_contact_open(const af_file *f, int r, int *failed);
void af_contact_close(af_contact *c);
int af_contact_count(const af_contact *c);
const char *af_contact_name(const af_contact *c, int i);
void af_contact_position(const af_contact *c, int i, double *position);
/* Obstacle i's kind (AF_PLANE ...) and its 15 numbers now (af_obstacle_shape). */
int af_contact_shape(const af_contact *c, int i, double *geometry);
/* Obstacle i to be at position (3) from the next step on, as far as the body lets it. */
void af_contact_move(af_contact *c, int i, const double *position);
/* A solve from q: the obstacles moved toward their targets, and with dt > 0 friction lagged
 * at q for a step of dt s. */
void af_contact_start(af_contact *c, const double *q, double dt);
/* The functions below take z: q (r) then the free obstacles' unknowns (af_contact_unknowns).
 * The barrier's and friction's energy at z (inf where a node reached an obstacle), the free
 * obstacles' inertia, their gradient (*g, n) and exact Hessian (*H, n x n) in the contact's
 * scratch, n = r + af_contact_unknowns, and
 * the floor R |H| (R the largest coordinate) of their round-off over eps. */
double af_contact_terms(af_contact *c, const double *z, const double **g, const double **H,
                        double *floor);
double af_contact_energy(af_contact *c, const double *z);
/* E(z + step) - E(z) (energy: E(z), after af_contact_terms at z), its first-order part
 * where the two differ by round-off. */
double af_contact_change(af_contact *c, const double *z, const double *step, double energy);
/* The largest share in (0, 1] of the step p (n) from z keeping every node clear. */
double af_contact_limit(af_contact *c, const double *z, const double *p);

/* Obstacle i free (mass > 0, kg) or moved only by af_contact_move (0), turning where inertia
 * (9, kg m^2 about its center) is not NULL, its center offset (3, m; NULL: zeros) from its
 * position; its velocity and the acceleration all else gives it (6 each: its center's, then
 * its spin's). */
void af_contact_motion(af_contact *c, int i, double mass, const double *inertia,
                       const double *offset, const double *velocity,
                       const double *acceleration);
/* Obstacle i to be turned by rotation (9, row-major) from how the file has it, about its
 * position, at the next step's start where no node then comes within a tenth of its gap. */
void af_contact_turn(af_contact *c, int i, const double *rotation);
/* The unknowns a step takes beside q since af_contact_start (3 per free obstacle, 6 where it
 * turns), and where its Newton starts them into y (that many): the move and turn at the
 * obstacles' velocity, dt v (the push a is left to the solve: a box resting on the body has
 * gravity's). */
long af_contact_unknowns(const af_contact *c);
void af_contact_guess(const af_contact *c, double *y);
/* A Newton iterate z (n) settled: each free obstacle's turn in z folded into its turn so far
 * and zeroed there (the contact's derivatives are taken at settled points). */
void af_contact_settle(af_contact *c, double *z);
/* Whether a free obstacle turns in this step (a step's collision test along a turn is along
 * its chord: its start is to be checked). */
int af_contact_turning(const af_contact *c);
/* After a solve ends at z: the free obstacles moved and turned by their part of z (their
 * velocity its share of dt; dt 0: a static solve), and each obstacle's wrench (force on it, N,
 * and moment about its center, N m) there. */
void af_contact_finish(af_contact *c, const double *z, double dt);
const double *af_contact_wrench(const af_contact *c, int i);
/* Where obstacle i's center is (3, m): its position, offset by af_contact_motion's offset. */
void af_contact_center(const af_contact *c, int i, double *center);

af_contact *af_reduced_contact(const af_reduced *m);

typedef struct af_framed af_framed;
af_framed *af_framed_open(const af_file *f, int n, const double *rest, const double *masses);
void af_framed_close(af_framed *m);
int af_framed_size(const af_framed *m);
void af_framed_rest(const af_framed *m, double *state);
/* base: 12 doubles, a rotation (row-major) and a translation: a rigid motion to 1e-9 */
int af_rigid(const double *base);
/* state (one copy: frames, coordinates, base) moved rigidly by base (R row-major, then t) */
void af_framed_carry(const af_framed *m, double *state, const double *base);
int af_framed_set_force(af_framed *m, const double *force);
int af_framed_advance(af_framed *m, const double *now, const double *before, double *next,
                      const double *force, const double *base, double dt, double tolerance,
                      int max_iter, char *error, size_t error_size);
void af_framed_place(const af_framed *m, const double *state, double *x);

#endif
