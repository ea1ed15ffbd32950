"""The ways to minimize a step's (or a static scene's) potential G, from exact to fast.

Every method is a source of search directions inside one loop (anisofem.solvers.newton.minimize):
the loop tests convergence, asks the method for directions and runs the backtracking line search
on G, so every method descends G, stops when the free-gradient norm meets the tolerance, and
reports failure instead of returning NaN. The methods differ in what a direction costs:

- "newton" (Newton): a fresh factorization of the Hessian every iteration (the true Hessian
  when it is positive definite, else the PSD-projected one). To rtol = 1e-8 it is the exact
  reference every other method is measured against.
- "reuse" (FactorReuse): keeps the last factorization across iterations and steps and
  refactors when a step with the kept factor leaves more than `refactor` of the gradient norm
  or fails to descend. The Hessian of a backward-Euler potential does not depend on x_hat, so
  a factor from a previous step is as good as one from an earlier iteration of the same step:
  what fixed-Hessian real-time FEM engines exploit. The kept factor is applied in each
  vertex's frame as it has turned since the factorization (anisofem.solvers.frames), so a bending
  body does not wear it out: on the trade cantilevers it refactors 3-4x less often than
  unturned (docs/experiments.md).
- "lbfgs" (LBFGS): limited-memory BFGS whose initial inverse Hessian is a factorized Hessian
  (Liu, Bouaziz and Kavan 2017, "Quasi-Newton methods for real-time simulation of
  hyperelastic materials"). Departures from the paper: the initial Hessian starts as the exact
  (PSD-projected) Hessian of G at rest instead of a Laplacian-like matrix, and is refactored
  at the current state as in "reuse" when a step makes too little progress. Kept constant, the
  rest Hessian of this anisotropic, nearly incompressible material is not rotation invariant:
  once a cantilever has bent, a full step with it raised G by 8x the predicted decrease, and a
  10-iteration L-BFGS stalled at step 68 of the 200-tet cantilever. The curvature pairs are
  kept across steps (valid for the same reason as in "reuse"), not restarted each frame, and
  pairs that violate the curvature condition are skipped.
- "cg" (NewtonCG): inexact Newton, preconditioned conjugate gradients on the assembled
  Hessian, stopped at a forcing tolerance eta times the gradient norm or after cg_iter
  iterations, and truncated at negative curvature (Steihaug); a first-iteration negative
  curvature retries with the projected Hessian. It does not step along negative curvature
  itself (measured: docs/experiments.md); where its solve fails, load continuation takes over
  (anisofem.solvers.continuation). eta follows how well the last iteration's
  quadratic model predicted the gradient it led to (Eisenstat and Walker 1996, choice 1):
  loose while the nonlinearity limits what a step can gain, tight once the model is good, so
  a solve spends its CG iterations where they buy progress (at 10^5 tets a backward-Euler
  step took 6.3 instead of 8.3 Newton and 85 instead of 108 CG iterations). The
  preconditioner is the Hessian's diagonal ("jacobi": no factorization, the rung that fits any
  memory) or a kept factorization of an earlier Hessian ("factor", renewed when CG needs more
  than refactor_after iterations): a lagged factor is a good preconditioner long after it has
  stopped being a good Hessian. With "amg" (a kept smoothed-aggregation multigrid hierarchy)
  neither time nor memory grows faster than the mesh: the large-mesh method.
- "auto" (the default of anisofem.solve, step and simulate): "newton" up to
  AUTO_MULTIGRID_MIN unknowns or wherever a linear_solver is named, "cg" with preconditioner
  "amg" above (choose).

Each method stops either at the tolerance (rtol, atol; max_iter a safety cap whose reaching is
a failure) or, with `iterations=k`, after a fixed budget of k iterations per solve: reaching
the budget is then the method working as asked (the result says converged=False, failed=False),
and rollouts continue. A rollout starts a tolerance-driven solve from the previous step's
acceleration, and a budgeted one from the inertial predictor x_n + dt v_n (zero acceleration;
option warm_start): truncated from an extrapolated start, one Newton iteration per step
diverged on the 200-tet cantilever and three L-BFGS iterations on the 12,800-tet one, while
from the predictor one Newton iteration is the linearly implicit Euler method, which is stable.
"""
from .kept_factor import LBFGS, FactorReuse
from .newton_cg import NewtonCG, forcing_tolerance, truncated_cg
from .newton_method import Method, Newton, gradient_tolerance, option_names

__all__ = ["METHODS", "AUTO_MULTIGRID_MIN", "choose", "make", "Method", "Newton", "FactorReuse",
           "LBFGS", "NewtonCG", "gradient_tolerance", "forcing_tolerance", "truncated_cg"]


METHODS = {cls.name: cls for cls in (Newton, FactorReuse, LBFGS, NewtonCG)}


#: What method="auto" solves with: exact Newton up to this many unknowns, inexact Newton with
#: the multigrid preconditioner ("cg", preconditioner "amg") above. Exact Newton's sparse
#: factorization grows faster than the mesh. Box cantilevers at nu = 0.48 and 0.499, static
#: solve and step (`python -m anisofem bench --crossover`): 3,780 unknowns, multigrid up to
#: 3.4x faster at nu = 0.48, exact Newton 1.5x faster at the nearly incompressible step;
#: 7,425, multigrid 1.7-5.9x faster, as fast at the nearly incompressible step; 13,728,
#: multigrid 2.5-7.9x faster; 66,150 (10^5 tets), multigrid 49x faster (`bench --large`).
AUTO_MULTIGRID_MIN = 5_000


def choose(n_unknowns, linear_solver=None):
    """The method "auto" picks for a problem of n_unknowns free components, given the
    linear_solver option or not: (name, options)."""
    if linear_solver is None and n_unknowns > AUTO_MULTIGRID_MIN:
        return "cg", {"preconditioner": "amg"}
    return "newton", {}


def make(method="auto", n_unknowns=None, **options):
    """A Method from a name ("auto" or one of METHODS) and its options, or a Method instance as
    is. n_unknowns: the problem's free components, which "auto" chooses by (see choose).
    "auto" takes Newton's options, which "cg" reads the same way; a linear_solver names a
    factorization and so makes it exact Newton at any size."""
    if isinstance(method, Method):
        if options:
            raise TypeError(f"{sorted(options)}: give options to the Method's constructor, "
                            f"not beside an instance")
        return method
    if method == "auto":
        knobs = option_names(Newton)
        unknown = sorted(set(options) - set(knobs))
        if unknown:
            raise TypeError(f"{unknown[0]}: not an option of method 'auto' (its options: "
                            f"{', '.join(knobs)}); name the method to set its own")
        if n_unknowns is None:
            raise ValueError("method 'auto' chooses by the problem's size: pass n_unknowns")
        method, chosen = choose(n_unknowns, options.get("linear_solver"))
        options = {**chosen, **options}
    if method not in METHODS:
        raise ValueError(f"method: expected one of {('auto',) + tuple(METHODS)} or an "
                         f"anisofem.solvers.methods.Method, got {method!r}")
    cls = METHODS[method]
    unknown = sorted(set(options) - set(option_names(cls)))
    if unknown:
        raise TypeError(f"{unknown[0]}: not an option of method {method!r} (its options: "
                        f"{', '.join(option_names(cls))})")
    return cls(**options)
