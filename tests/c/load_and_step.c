/* For tests/test_c_checks.py: load each file named on the command line with af_load and print
 * one line per file, "ok KIND N STEPS LOWEST" after 50 steps under the file's gravity, or
 * "error MESSAGE" where it cannot be loaded or stepped. Built with the sanitizers, it shows
 * that no file, good or corrupt, reads memory it should not. */
#include <stdio.h>
#include <stdlib.h>

#include "anisofem.h"

int main(int argc, char **argv) {
    int a;
    for (a = 1; a < argc; a++) {
        char error[512];
        double g[3] = {0.0, 0.0, -9.81}, lowest = 1e300, *state, *force, *x;
        int n, i, k, code = AF_OK;
        af_model *m = af_load(argv[a], NULL, error, sizeof error);
        if (!m) {
            printf("error %s\n", error);
            continue;
        }
        n = af_vertices(m);
        af_gravity(m, g);
        state = (double *)malloc((size_t)af_state_size(m) * sizeof(double));
        force = (double *)malloc((size_t)(3 * n) * sizeof(double));
        x = (double *)malloc((size_t)(3 * n) * sizeof(double));
        af_rest_state(m, state);
        for (i = 0; i < 3 * n; i++) force[i] = af_masses(m)[i / 3] * g[i % 3];
        for (k = 0; k < 50 && code == AF_OK; k++) code = af_step(m, state, force, NULL, 0.02);
        if (code == AF_OK) {
            af_positions(m, state, x);
            for (i = 0; i < n; i++) if (x[3 * i + 2] < lowest) lowest = x[3 * i + 2];
            printf("ok %d %d %d %.17g\n", af_kind(m), n, k, lowest);
        } else {
            printf("error %s\n", af_error(m));
        }
        free(state); free(force); free(x);
        af_free(m);
    }
    return 0;
}
