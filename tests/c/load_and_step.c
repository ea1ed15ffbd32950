/* For tests/test_c_checks.py: load each file named on the command line with af_load and print
 * one line per file, "ok KIND N STEPS LOWEST" after 50 steps under the file's gravity (and
 * for a file with controls, set anew every step, " controls K reach CODE" after one af_reach
 * of vertex 0; for a file with obstacles, each moved up by 2 mm every 10 steps and the last
 * also free and turning (10 g rising at 5 cm/s), " obstacles O HEIGHT", HEIGHT where the first
 * is then),
 * or "error MESSAGE" where it cannot be loaded or
 * stepped. Built with the sanitizers, it shows that no file, good or corrupt, reads memory it
 * should not. */
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
        af_set_constant_force(m, NULL);
        if (af_obstacles(m)) {
            double up[6] = {0.0, 0.0, 0.05, 0.0, 0.0, 0.0}, none[6] = {0.0}, shape[15];
            double inertia[9] = {1e-5, 0.0, 0.0, 0.0, 1e-5, 0.0, 0.0, 0.0, 1e-5}, middle[3];
            int last = af_obstacles(m) - 1, kind = af_obstacle_shape(m, last, shape);
            for (i = 0; i < 3; i++)      /* a capsule turns about its middle */
                middle[i] = kind == AF_CAPSULE ? 0.5 * (shape[3 + i] - shape[i]) : 0.0;
            code = af_obstacle_motion(m, last, 0.01, inertia, middle, up, none);
        }
        for (k = 0; k < 50 && code == AF_OK; k++) {
            double values[64];
            for (i = 0; i < af_controls(m) && i < 64; i++) values[i] = 0.05 * ((k + i) % 2);
            if (af_controls(m)) code = af_set_controls(m, values);
            for (i = 0; i < af_obstacles(m) && k % 10 == 9 && code == AF_OK; i++) {
                double at[3];
                af_obstacle_position(m, i, at);
                at[2] += 2e-3;
                code = af_move_obstacle(m, i, at);
            }
            if (code == AF_OK) code = af_step(m, state, force, NULL, 0.02);
        }
        if (code == AF_OK) {
            af_positions(m, state, x);
            for (i = 0; i < n; i++) if (x[3 * i + 2] < lowest) lowest = x[3 * i + 2];
            printf("ok %d %d %d %.17g", af_kind(m), n, k, lowest);
            if (af_controls(m) && af_controls(m) <= 64) {
                double low[64], high[64], found[64], at[3], target[3];
                int node = 0;
                double one = 1.0;
                for (i = 0; i < af_controls(m); i++) {
                    low[i] = 0.0;
                    high[i] = 0.1;
                }
                for (i = 0; i < 3; i++) target[i] = af_rest_positions(m)[i] + 1e-3;
                af_set_constant_force(m, force);
                code = af_reach(m, &node, &one, 1, target, low, high, 0.0, found, at);
                printf(" controls %d reach %d", af_controls(m), code);
            }
            if (af_obstacles(m)) {
                double at[3];
                af_obstacle_position(m, 0, at);
                printf(" obstacles %d %.17g", af_obstacles(m), at[2]);
            }
            printf("\n");
        } else {
            printf("error %s\n", af_error(m));
        }
        free(state); free(force); free(x);
        af_free(m);
    }
    return 0;
}
