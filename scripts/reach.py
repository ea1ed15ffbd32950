"""How far anisofem's one-step response reaches, in mesh hops (docs/experiments.md).

    python scripts/reach.py [--steps 6 12] [--other]

For each training geometry (anisognn.sampler.geometries) and each evaluation cantilever, at
rest under the shipped time step (0.02 s) and the paper's material with kappa = E along x:
the hops from the clamp to the farthest vertex, and the share (mass norm) of the response
H^-1 e to a unit point force e at a free vertex that lies farther than k hops from it, averaged
over every free vertex and axis. A network with k message-passing steps sees k hops, so this
share is what it cannot represent of a point load's step. --other measures instead the scenes
of scripts/seeds.py that are not of the training family's size (refined, longer, T and Y;
their own clamps and fibers), from SOURCES free vertices drawn with a fixed seed. Run with
OMP_NUM_THREADS=1.
"""
import argparse

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from scipy.sparse.csgraph import shortest_path

import anisofem
from anisofem import Material, Scene
from anisognn import evaluate
from anisognn.sampler import DENSITY, POISSON, YOUNG, geometries
from seeds import TRAINING_SIZE, scenes

DT = 0.02
#: free vertices sampled as point-load sources on the larger scenes (--other)
SOURCES = 60


def hop_table(mesh):
    """(n, n) hops between vertices along mesh edges."""
    e, n = mesh.edges, mesh.n_vertices
    adjacency = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return shortest_path(adjacency + adjacency.T, unweighted=True)


def clamped_at_x0(mesh):
    """The Scene of mesh held at x = 0, the paper's material with kappa = E along x."""
    return Scene(mesh, Material(YOUNG, POISSON, DENSITY, np.array([1.0, 0, 0]), YOUNG),
                 fixed=mesh.vertices[:, 0] <= 1e-9)


def reach(scene, steps, sources=None):
    """(hops from the clamp to the farthest vertex, {k: share of the response beyond k hops})
    of scene at rest, over every free vertex as the point-load source, or over `sources` of
    them drawn with seed 0."""
    mesh = scene.mesh
    fixed = scene.fixed_mask.all(axis=1)
    X = mesh.vertices
    free = np.repeat(~fixed, 3)
    H = anisofem.hessian(scene, X, x_hat=X, dt=DT).tocsc()
    lu = sla.splu(H[free][:, free].tocsc())
    hops = hop_table(mesh)
    n = mesh.n_vertices
    shares = {k: [] for k in steps}
    loaded = np.flatnonzero(~fixed)
    if sources is not None and sources < len(loaded):
        loaded = np.sort(np.random.default_rng(0).choice(loaded, sources, replace=False))
    for i in loaded:
        for axis in range(3):
            rhs = np.zeros(3 * n)
            rhs[3 * i + axis] = 1.0
            u = np.zeros(3 * n)
            u[free] = lu.solve(rhs[free])
            weight = scene.masses * (u.reshape(n, 3) ** 2).sum(axis=1)
            for k in steps:
                shares[k].append(weight[hops[i] > k].sum() / weight.sum())
    return int(hops[fixed].min(axis=0).max()), {k: float(np.mean(v)) for k, v in shares.items()}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, nargs="+", default=[6, 12])
    parser.add_argument("--other", action="store_true",
                        help="the scenes of scripts/seeds.py beyond the training family's size")
    args = parser.parse_args()
    if args.other:
        cases = [(f"{label}: {s.mesh.n_tets} tets", s, SOURCES)
                 for label, s in list(scenes().items())[TRAINING_SIZE:]]
    else:
        cases = [(f"training {k}: {m.n_tets} tets", clamped_at_x0(m), None)
                 for k, m in enumerate(geometries())]
        cases += [(f"evaluation {kind}: {m.n_tets} tets", clamped_at_x0(m), None)
                  for kind, m in (("box", evaluate._beam("box")),
                                  ("cylinder", evaluate._beam("cylinder")))]
    width = max(len(c[0]) for c in cases)
    print(f"{'mesh':<{width}} {'hops from clamp':>15} " + " ".join(f"{'> %d hops' % k:>10}"
                                                                   for k in args.steps))
    for label, scene, sources in cases:
        diameter, shares = reach(scene, args.steps, sources)
        print(f"{label:<{width}} {diameter:>15d} " + " ".join(f"{shares[k]:>10.3f}"
                                                              for k in args.steps), flush=True)


if __name__ == "__main__":
    main()
