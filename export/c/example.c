/* Step a model file (reduced or framed) under gravity from rest and print its lowest vertex
 * height per step.
 *
 *   cc -std=c99 -O2 -o example example.c arrays.c linalg.c reduced.c framed.c model.c files.c -lm
 *   ./example cantilever 100 0.02            # PATH (no extension), steps, dt (s)
 */
#include <stdio.h>
#include <stdlib.h>

#include "anisofem.h"

int main(int argc, char **argv) {
    char error[512];
    af_model *model;
    double *state, *gravity, *x, dt, g[3] = {0.0, 0.0, -9.81};
    int n, steps, k, i;
    if (argc != 4) {
        fprintf(stderr, "usage: %s PATH STEPS DT\n", argv[0]);
        return 2;
    }
    model = af_load(argv[1], NULL, error, sizeof error);
    if (!model) {
        fprintf(stderr, "%s\n", error);
        return 1;
    }
    n = af_vertices(model);
    steps = atoi(argv[2]);
    dt = atof(argv[3]);
    af_gravity(model, g);                          /* the file's, where it states one */
    state = (double *)malloc((size_t)af_state_size(model) * sizeof *state);
    gravity = (double *)malloc((size_t)n * 3 * sizeof *gravity);
    x = (double *)malloc((size_t)n * 3 * sizeof *x);
    af_rest_state(model, state);
    for (i = 0; i < 3 * n; i++) gravity[i] = g[i % 3] * af_masses(model)[i / 3];
    af_set_constant_force(model, gravity);         /* projected once */
    for (k = 0; k < steps; k++) {
        double lowest = 1e300;
        if (af_step(model, state, NULL, NULL, dt) != AF_OK) {   /* no other force */
            fprintf(stderr, "step %d: %s\n", k, af_error(model));
            return 1;
        }
        af_positions(model, state, x);
        for (i = 0; i < n; i++) if (x[3 * i + 2] < lowest) lowest = x[3 * i + 2];
        printf("%.17g\n", lowest);
    }
    free(state); free(gravity); free(x);
    af_free(model);
    return 0;
}
