"""The physics: meshes and their generators, elements (linear and quadratic tets), energy
densities and materials, fiber fields, loads (pressure, load curves), the numba kernels and
their assembly, the scene and its potential (energy, gradient, PSD-projected Hessian), and the
measures the paper takes of an answer. Imports nothing of anisofem's but its base modules
(`anisofem._validate`, `anisofem.threads`)."""
