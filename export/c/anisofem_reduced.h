/* A reduced model written by `python -m export reduced` (PATH.json + PATH.bin), stepped by
 * backward Euler in C99 with no dependency: the same step as export/runtime.py's
 * ReducedSimulator, in double precision.
 *
 *   char err[256];
 *   af_reduced *m = af_reduced_load("cantilever", NULL, err, sizeof err);
 *   double *q = calloc(af_reduced_coordinates(m), sizeof(double));   // rest state: zeros
 *   double *w = calloc(af_reduced_coordinates(m), sizeof(double));
 *   af_reduced_step(m, q, w, force, 0.02, 1e-8, 50);   // force: n x 3 N per vertex
 *   af_reduced_positions(m, q, x);                      // x: n x 3 m
 *   af_reduced_free(m);
 *
 * Units SI: positions m, forces N, time s. Arrays are row-major, vertex by vertex (x0 y0 z0 x1
 * ...). Every function that can fail returns a negative AF_* code (or NULL) and, where given a
 * buffer, a message in it.
 */
#ifndef ANISOFEM_REDUCED_H
#define ANISOFEM_REDUCED_H

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
    AF_BAD_FILE = -1,      /* the file is missing, not a reduced model, or of another version */
    AF_BAD_INPUT = -2,     /* a non-finite force or state, or dt <= 0 */
    AF_NOT_CONVERGED = -3, /* Newton stopped short of its tolerance (the state is unchanged) */
    AF_NO_MEMORY = -4
};

typedef struct af_reduced af_reduced;

/* Load PATH.json + PATH.bin (path without extension). angle: NULL for a file of one model, or
 * the fiber angle to step in a file of several (`python -m export bake-reduced`), e.g. "30".
 * Returns NULL on failure with the reason in error (error_size bytes, may be 0). */
AF_API af_reduced *af_reduced_load(const char *path, const char *angle, char *error,
                                   size_t error_size);
AF_API void af_reduced_free(af_reduced *model);

/* n, the vertices the model moves; r, its reduced coordinates. */
AF_API int af_reduced_vertices(const af_reduced *model);
AF_API int af_reduced_coordinates(const af_reduced *model);
/* The vertices' lumped masses (n,), kg, and rest positions (n x 3), m. */
AF_API const double *af_reduced_masses(const af_reduced *model);
AF_API const double *af_reduced_rest_positions(const af_reduced *model);

/* A force (n x 3, N) added to every later step (gravity: masses times g), projected once
 * here so that a step need not project it again (that projection, n x 3 x r, is most of a
 * step's time on large meshes). NULL clears it. Returns AF_OK or AF_BAD_INPUT (non-finite). */
AF_API int af_reduced_set_constant_force(af_reduced *model, const double *force);

/* One backward-Euler step of dt s from reduced coordinates q (r,) and velocities w (r,), in
 * place, under the constant force plus nodal forces force (n x 3, N; NULL: none). rtol: the
 * reduced gradient's tolerance over the step's force size (1e-8); max_iter: Newton's budget
 * (50). Returns AF_OK, or a negative code with q and w unchanged. */
AF_API int af_reduced_step(af_reduced *model, double *q, double *w, const double *force,
                           double dt, double rtol, int max_iter);
/* The Newton iterations of the last step. */
AF_API int af_reduced_iterations(const af_reduced *model);

/* Positions x (n x 3), m, of reduced coordinates q (r,). */
AF_API void af_reduced_positions(const af_reduced *model, const double *q, double *x);

/* ---------------------------------------------------------------------------------------
 * A framed model (`python -m export reduced --framed`, or `bake-reduced --framed` with an
 * angle): domains in their own rotating frames, for bodies that bend and swing far; the step
 * of export/framed_runtime.py's FramedSimulator. A state is af_framed_state_size doubles:
 * each domain's centre (3 D, m), rotation (9 D, row-major) and coordinates (Q), then the base
 * (12: a rotation R_g, row-major, and a translation c_g, m) that carries the held vertices,
 * x = R_g x0 + c_g. A file written for a display mesh (`--display`) takes forces and gives
 * positions on the display's vertices (af_framed_vertices of them).
 *
 *   af_framed *m = af_framed_load("t", NULL, err, sizeof err);
 *   int size = af_framed_state_size(m);
 *   double *now = malloc(size * sizeof(double)), *before = ..., *next = ...;
 *   af_framed_rest_state(m, now); af_framed_rest_state(m, before);
 *   af_framed_set_constant_force(m, gravity);                     // once (n x 3, N)
 *   af_framed_step(m, now, before, next, drag, NULL, 0.02, 50);   // before = now, now = next
 *   af_framed_positions(m, next, x);
 */
typedef struct af_framed af_framed;

AF_API af_framed *af_framed_load(const char *path, const char *angle, char *error,
                                 size_t error_size);
AF_API void af_framed_free(af_framed *model);
AF_API int af_framed_vertices(const af_framed *model);
AF_API int af_framed_state_size(const af_framed *model);
AF_API const double *af_framed_masses(const af_framed *model);
AF_API const double *af_framed_rest_positions(const af_framed *model);
/* The rest state: every frame at its domain's rest centre, unturned, q = 0. */
AF_API void af_framed_rest_state(const af_framed *model, double *state);
/* A nodal force (n x 3, N) every step adds to its own, gravity say: its projection is stored
 * once (the per-step force then need only hold drags). NULL clears it. Returns AF_OK or
 * AF_BAD_INPUT (non-finite). */
AF_API int af_framed_set_constant_force(af_framed *model, const double *force);
/* One backward-Euler step of dt s after the state now (before: the state a step earlier, now
 * itself from rest) into next, under the constant force plus nodal forces force (n x 3, N;
 * NULL: none); base (12 doubles: R_g row-major, c_g) where the held vertices are at the
 * step's end (a hand or a character carrying the body), or NULL to keep now's. Returns
 * AF_OK, or a negative code
 * (AF_BAD_INPUT: a non-finite force or state, dt <= 0, a base that is not a rigid motion)
 * with next unchanged. */
AF_API int af_framed_step(af_framed *model, const double *now, const double *before,
                          double *next, const double *force, const double *base, double dt,
                          int max_iter);
AF_API int af_framed_iterations(const af_framed *model);
/* Positions x (n x 3), m, of a state. */
AF_API void af_framed_positions(const af_framed *model, const double *state, double *x);

#ifdef __cplusplus
}
#endif

#endif
