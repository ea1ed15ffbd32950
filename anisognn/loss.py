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
the sum with newton_weight = beta weighs mode k by lambda_k + beta.
"""
import numpy as np
import torch

from anisofem import linsolve
from anisofem.potential import Potential


class BatchPotential:
    """The incremental potentials of the scenes of a batch, on their slices of the stacked
    (N, 3) positions. potentials: anisofem Potentials (one per scene, same order as the batch);
    weights: (scenes,) multipliers of each G_i (default 1)."""

    def __init__(self, potentials, weights=None):
        self.potentials = list(potentials)
        sizes = [p.scene.mesh.n_vertices for p in self.potentials]
        self.offsets = np.concatenate([[0], np.cumsum(sizes)])
        self.weights = np.ones(len(sizes)) if weights is None else np.asarray(weights, float)

    @classmethod
    def backward_euler(cls, scenes, x, v, dt, weights=None):
        """Potentials of one backward-Euler step from stacked x, v (N, 3) numpy float64."""
        pots, start = [], 0
        for scene in scenes:
            n = scene.mesh.n_vertices
            pots.append(Potential(scene, x[start:start + n] + dt * v[start:start + n], dt))
            start += n
        return cls(pots, weights)

    def energy_gradient(self, x, newton_weight=0.0):
        """(sum_i w_i G_i in J, its gradient (N, 3) in N, plus newton_weight times the Newton
        term sum_i w_i (M_i/dt^2) H_i^-1 dG_i/dx on free components) at stacked positions
        x (N, 3) float64."""
        total, grad = 0.0, np.empty_like(x)
        for w, pot, lo, hi in zip(self.weights, self.potentials, self.offsets[:-1],
                                  self.offsets[1:]):
            if newton_weight == 0:
                e, g = pot.energy_gradient(x[lo:hi])
            else:
                e, g = _with_newton_term(pot, x[lo:hi], newton_weight)
            total += w * e
            grad[lo:hi] = w * g
        return total, grad


def _with_newton_term(pot, x, newton_weight):
    """(G in J, dG/dx + newton_weight (M/dt^2) H^-1 dG/dx (n, 3) in N) of one scene's
    Potential at x (n, 3); H is the projected Hessian over the free components."""
    solver = linsolve.make("auto", pot.scene.n_free)
    layout = pot.scene.layout(solver.layout)
    with solver.threads():
        e, g, data = pot.hessian_data(x, layout, project=True)
        step = solver.factor(layout, data)(g.reshape(-1)[layout.dofs])
    g.reshape(-1)[layout.dofs] += newton_weight * pot.mass_per_dof[layout.dofs] * step
    return e, g


class _PotentialFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x_next, batch_potential, newton_weight):
        x64 = x_next.detach().to("cpu", torch.float64).numpy()
        energy, grad = batch_potential.energy_gradient(x64, newton_weight)
        ctx.save_for_backward(torch.from_numpy(grad).to(x_next.device, x_next.dtype))
        return x_next.new_tensor(energy)

    @staticmethod
    def backward(ctx, grad_output):
        (grad,) = ctx.saved_tensors
        return grad_output * grad, None, None


def potential_loss(x_next, batch_potential, newton_weight=0.0):
    """sum_i w_i G_i(x_next) as a scalar tensor (x_next's dtype and device), J; its gradient
    with respect to x_next (N, 3) is anisofem's dG/dx plus newton_weight times the Newton-
    preconditioned (M/dt^2) H^-1 dG/dx (see the module docstring)."""
    if not newton_weight >= 0:
        raise ValueError(f"newton_weight: must be >= 0, got {newton_weight}")
    return _PotentialFunction.apply(x_next, batch_potential, float(newton_weight))
