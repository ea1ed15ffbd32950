"""`python -m export reduced SCENE -o PATH`: a scene's reduced model (anisofem.reduced) written
as PATH.json + PATH.bin (export.bake.write_arrays), which runtime.ReducedSimulator steps with
numpy alone.

The arrays (float64 unless said): rest_positions (n, 3) m, the positions the basis moves;
basis (n, 3, r) m per unit of q, 0 on held components; c1 (r,), C2 (r, r), S3 (r, r, r) and
W4 (T, r), T = r (r + 1) (r + 2) / 6, the coefficients of the energy (runtime.ReducedSimulator);
masses (n,) kg; held (n, 3) uint8; tets (m, 4) int32, the mesh it was built on; surface (k, 3)
int32, the boundary triangles. The header: model_format REDUCED_FORMAT, title, n, m, r, modes,
frequencies (Hz), c0 (J), build_seconds, validation (the static tip and field errors against
the full FEM), gravity (m/s^2) and material.
"""
import dataclasses

import numpy as np

from . import runtime
from .bake import write_arrays


def write(model, path, title="", gravity=None):
    """Write the ReducedModel `model` as path.json and path.bin; returns the header. gravity
    (3,) m/s^2: the scene's, recorded for a viewer (the runtime takes forces per step)."""
    scene, P = model.scene, model.polynomial
    n, r = scene.mesh.n_vertices, model.r
    arrays = {"rest_positions": model.x0, "basis": model.basis.reshape(n, 3, r),
              "c1": P.c1, "C2": P.C2, "S3": P.S3, "W4": P.W4,
              "masses": np.asarray(scene.masses, dtype=np.float64),
              "held": scene.fixed_mask.astype(np.uint8),
              "tets": scene.mesh.tets.astype(np.int32),
              "surface": runtime.surface_triangles(scene.mesh.vertices,
                                                   scene.mesh.tets).astype(np.int32)}
    material = scene.material
    header = {"model_format": runtime.REDUCED_FORMAT, "title": title, "n": n,
              "m": scene.mesh.n_tets, "r": r, "modes": len(model.frequencies),
              "frequencies": [float(f) for f in model.frequencies], "c0": float(P.c0),
              "build_seconds": model.build_seconds,
              "validation": (None if model.validation is None
                             else dataclasses.asdict(model.validation)),
              "gravity": None if gravity is None else [float(g) for g in gravity],
              "material": {key: np.asarray(getattr(material, key)).tolist()
                           for key in ("young", "poisson", "density")}}
    write_arrays(path, arrays, header)
    return header
