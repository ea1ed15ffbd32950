// A C++17 program over the C runtime: step a model file (reduced or framed) from rest under
// gravity and a drag on its top vertex for the first half of the steps, and print the lowest
// vertex height per step.
//
//   c++ -std=c++17 -O2 -o example example.cpp arrays.c linalg.c reduced.c framed.c model.c files.c
//   ./example tentacle 200 0.02            # PATH (no extension), steps, dt (s)
//
// (The runtime's sources compile as C++ too; or build them as C with the CMakeLists.txt beside
// them and link libanisofem.)
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <vector>

#include "anisofem.h"

int main(int argc, char **argv) {
    if (argc != 4) {
        std::fprintf(stderr, "usage: %s PATH STEPS DT\n", argv[0]);
        return 2;
    }
    char error[512];
    std::unique_ptr<af_model, decltype(&af_free)> model(af_load(argv[1], nullptr, error,
                                                               sizeof error), af_free);
    if (!model) {
        std::fprintf(stderr, "%s\n", error);
        return 1;
    }
    af_model *m = model.get();
    const int n = af_vertices(m), steps = std::atoi(argv[2]);
    const double dt = std::atof(argv[3]);
    double g[3] = {0.0, 0.0, -9.81};
    af_gravity(m, g);                                      // the file's, where it states one
    std::vector<double> state(af_state_size(m)), gravity(3 * n), drag(3 * n), x(3 * n);
    af_rest_state(m, state.data());
    const double *mass = af_masses(m), *rest = af_rest_positions(m);
    int top = 0;
    for (int i = 0; i < n; ++i) {
        for (int c = 0; c < 3; ++c) gravity[3 * i + c] = mass[i] * g[c];
        if (rest[3 * i + 2] > rest[3 * top + 2]) top = i;
    }
    af_set_constant_force(m, gravity.data());              // projected once
    drag[3 * top] = 0.5 * mass[top] * 9.81;                // sideways, on the top vertex
    for (int k = 0; k < steps; ++k) {
        if (af_step(m, state.data(), k < steps / 2 ? drag.data() : nullptr, nullptr, dt) != AF_OK) {
            std::fprintf(stderr, "step %d: %s\n", k, af_error(m));
            return 1;
        }
        af_positions(m, state.data(), x.data());
        double lowest = 1e300;
        for (int i = 0; i < n; ++i) lowest = x[3 * i + 2] < lowest ? x[3 * i + 2] : lowest;
        std::printf("%.17g\n", lowest);
    }
    return 0;
}
