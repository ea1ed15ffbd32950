"""Studies that measure the library: the speed/accuracy ladder (`trade`), the benchmarks
(`bench`, `bench_large`, `bench_load`, `bench_distributed`), the sag's convergence under
refinement, the robustness grid and the uniaxial rod's closed form. They may import every
other concern; nothing but the command line imports them, and `anisofem.trade`."""
