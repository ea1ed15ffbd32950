"""The physics loss: anisofem's backward-Euler incremental potential of the predicted next
positions, with anisofem's hand-derived gradient as the backward pass (one implementation of
the physics; nothing here re-derives it in torch).

For one scene with state (x_n, v_n), the network's acceleration a gives
x_{n+1} = x_n + dt v_n + dt^2 a (held components at their prescribed positions), and

    G(x_{n+1}) = 1/(2 dt^2) |x_{n+1} - x_n - dt v_n|_M^2 + Psi(x_{n+1}) - f_ext . x_{n+1}   (J)

whose minimizer is the backward-Euler step. A batch is a disjoint union of scenes; the loss
is sum_i weight_i G_i over its scenes.

Its gradient with respect to x_next is dG/dx + newton_weight (M/dt^2) H^-1 dG/dx, H the
PSD-projected Hessian of G at x_next (plus M/dt^2: positive definite). newton_weight = 0 is the
paper's plain energy gradient. The second term is the gradient of
1/2 |x_next - sg(x_next - H^-1 dG/dx)|^2_{M/dt^2}, a regression onto the detached Newton target:
same minimizer (the backward-Euler step), no data. Why: in mass-weighted coordinates dG/dx weighs
each mode's error by its eigenvalue, about 1 for the soft bending modes (inertia-dominated at
dt = 0.02 s) and up to ~4e4 for the volumetric ones (nu = 0.48, 1 cm elements), so plain
gradients learn the modes that show, bending under load, very slowly; the Newton term weighs
every mode alike. Alone it neglects the stiff modes, whose small errors then cost much energy;
the sum with newton_weight = beta weighs mode k by lambda_k + beta; energy_weight = 0 leaves the
Newton term alone, a regression onto a target that anisofem recomputes from every prediction.

normalize = True divides each scene's terms by its optimal decrease D = 1/2 g0^T H0^-1 g0 from
the zero-acceleration start x_hat (held components at their prescribed positions), the
decrease one Newton step promises there: every sample then weighs alike, whatever its load
(without it a batch's gradient is the few heavily loaded samples').
"""
import numpy as np
import torch

from anisofem.solvers import linsolve
from anisofem.physics.potential import Potential


class BatchPotential:
    """The incremental potentials of the scenes of a batch, on their slices of the stacked
    (N, 3) positions. potentials: anisofem Potentials (one per scene, same order as the batch);
    weights: (scenes,) multipliers of each scene's loss (default 1)."""

    def __init__(self, potentials, weights=None):
        self.potentials = list(potentials)
        sizes = [p.scene.mesh.n_vertices for p in self.potentials]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)])
        self.weights = np.ones(len(sizes)) if weights is None else np.asarray(weights, float)

    @classmethod
    def backward_euler(cls, scenes, x, v, dt, weights=None, normalize=False):
        """Potentials of one backward-Euler step from stacked x, v (N, 3) numpy float64;
        normalize: divide each weight by the scene's optimal decrease (module docstring)."""
        pots, start = [], 0
        for scene in scenes:
            n = scene.mesh.n_vertices
            pots.append(Potential(scene, x[start:start + n] + dt * v[start:start + n], dt))
            start += n
        weights = np.ones(len(pots)) if weights is None else np.asarray(weights, float)
        if normalize:
            weights = weights / np.array([optimal_decrease(p) for p in pots])
        return cls(pots, weights)

    def energy_gradient(self, x, newton_weight=0.0, energy_weight=1.0):
        """(loss in J, its gradient (N, 3) in N) at stacked positions x (N, 3) float64: the sum
        over scenes of w_i (energy_weight G_i + newton_weight 1/2 |s_i|^2_{W_i}) with
        s_i = H_i^-1 dG_i/dx (module docstring), the gradient with the Newton term W_i s_i on
        free components."""
        total, grad = 0.0, np.empty_like(x)
        for w, pot, lo, hi in zip(self.weights, self.potentials, self.offsets[:-1],
                                  self.offsets[1:]):
            if newton_weight == 0:
                e, g = pot.energy_gradient(x[lo:hi])
                e, g = energy_weight * e, energy_weight * g
            else:
                e, g = _with_newton_term(pot, x[lo:hi], newton_weight, energy_weight)
            total += w * e
            grad[lo:hi] = w * g
        return total, grad


def _newton_step(pot, x):
    """(G in J, dG/dx (n, 3) in N, free DOF indices, H^-1 dG/dx on them in m) of one scene's
    Potential at x (n, 3); H is the projected Hessian over the free components."""
    solver = linsolve.make("auto", pot.scene.n_free)
    layout = pot.scene.layout(solver.layout)
    with solver.threads():
        e, g, data = pot.hessian_data(x, layout, project=True)
        step = solver.factor(layout, data)(g.reshape(-1)[layout.dofs])
    return e, g, layout.dofs, step


def optimal_decrease(pot):
    """1/2 g0^T H0^-1 g0 in J at the zero-acceleration start of a backward-Euler Potential
    (x_hat with the held components at their prescribed positions), floored at 1e-15 J."""
    _, g, dofs, step = _newton_step(pot, pot.scene.with_fixed(pot.x_hat))
    return max(0.5 * float(g.reshape(-1)[dofs] @ step), 1e-15)


def _with_newton_term(pot, x, newton_weight, energy_weight):
    """(energy_weight G + newton_weight 1/2 |s|^2_W in J, energy_weight dG/dx + newton_weight
    W s (n, 3) in N) with s the Newton step at x (n, 3) and W = M/dt^2."""
    e, g, dofs, step = _newton_step(pot, x)
    scaled = pot.mass_per_dof[dofs] * step
    g *= energy_weight
    g.reshape(-1)[dofs] += newton_weight * scaled
    return energy_weight * e + 0.5 * newton_weight * float(step @ scaled), g


class _PotentialFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x_next, batch_potential, newton_weight, energy_weight):
        x64 = x_next.detach().to("cpu", torch.float64).numpy()
        energy, grad = batch_potential.energy_gradient(x64, newton_weight, energy_weight)
        ctx.save_for_backward(torch.from_numpy(grad).to(x_next.device, x_next.dtype))
        return x_next.new_tensor(energy)

    @staticmethod
    def backward(ctx, grad_output):
        (grad,) = ctx.saved_tensors
        return grad_output * grad, None, None, None


def potential_loss(x_next, batch_potential, newton_weight=0.0, energy_weight=1.0):
    """The loss of BatchPotential.energy_gradient at x_next (N, 3) as a scalar tensor (x_next's
    dtype and device), J, with that gradient as its backward (see the module docstring)."""
    for name, value in (("newton_weight", newton_weight), ("energy_weight", energy_weight)):
        if not value >= 0:
            raise ValueError(f"{name}: must be >= 0, got {value}")
    if newton_weight == 0 and energy_weight == 0:
        raise ValueError("newton_weight, energy_weight: at least one must be > 0")
    return _PotentialFunction.apply(x_next, batch_potential, float(newton_weight),
                                    float(energy_weight))
