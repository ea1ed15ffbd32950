/* Step a reduced model under gravity from rest and print its lowest vertex height per step.
 *
 *   cc -std=c99 -O2 -o example example.c anisofem_reduced.c -lm
 *   ./example cantilever 100 0.02            # PATH (no extension), steps, dt (s)
 */
#include <stdio.h>
#include <stdlib.h>

#include "anisofem_reduced.h"

int main(int argc, char **argv) {
    char error[512];
    af_reduced *model;
    double *q, *w, *force, *x, dt;
    int n, r, steps, k, i;
    if (argc != 4) {
        fprintf(stderr, "usage: %s PATH STEPS DT\n", argv[0]);
        return 2;
    }
    model = af_reduced_load(argv[1], NULL, error, sizeof error);
    if (!model) {
        fprintf(stderr, "%s\n", error);
        return 1;
    }
    n = af_reduced_vertices(model);
    r = af_reduced_coordinates(model);
    steps = atoi(argv[2]);
    dt = atof(argv[3]);
    q = calloc((size_t)r, sizeof *q);
    w = calloc((size_t)r, sizeof *w);
    force = calloc((size_t)n * 3, sizeof *force);
    x = malloc((size_t)n * 3 * sizeof *x);
    for (i = 0; i < n; i++) force[3 * i + 2] = -9.81 * af_reduced_masses(model)[i];
    af_reduced_set_constant_force(model, force);   /* gravity, projected once */
    for (k = 0; k < steps; k++) {
        double lowest = 1e300;
        int code = af_reduced_step(model, q, w, NULL, dt, 1e-8, 50);   /* no other force */
        if (code != AF_OK) {
            fprintf(stderr, "step %d: code %d\n", k, code);
            return 1;
        }
        af_reduced_positions(model, q, x);
        for (i = 0; i < n; i++) if (x[3 * i + 2] < lowest) lowest = x[3 * i + 2];
        printf("%.17g\n", lowest);
    }
    free(q); free(w); free(force); free(x);
    af_reduced_free(model);
    return 0;
}
