"""Cubature (An, Kim and James 2008): a few elements with non-negative weights whose weighted
generalized forces match the sum over all of them on training poses, so that a reduced
model evaluates those few instead of all.

The elements are chosen greedily: each round adds the element whose forces best correlate
with what the chosen ones, weighted by non-negative least squares, still miss.
"""
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular
from scipy.optimize import nnls


@dataclass
class Cubature:
    """A cubature: elements (k,) the chosen ones' indices among those fitted; weights (k,) > 0
    their weights; of, how many elements it was fitted from; residual, the share of the
    training forces the weighted sum misses, |A w - A 1| / |A 1| over all poses stacked (A:
    the elements' forces, a column each); seconds, its fit's time with the training poses'."""
    elements: np.ndarray
    weights: np.ndarray
    of: int
    residual: float
    seconds: float = 0.0


def select(forces, residual, most):
    """Cubature of `forces` (p, m): row i holds each of m elements' share of training
    quantity i (a generalized force on one pose, scaled as the fit should weigh it). Adds
    elements until the weighted sum of their columns is within `residual` (a share) of the sum
    of all m columns, or `most` are chosen. Returns (indices (k,), weights (k,) > 0, the
    share missed).

    Each round's non-negative least squares runs on the chosen columns' Gram matrix G = L L^T
    (k x k, grown a column a round): |A w - b|^2 = |L^T w - L^-1 A^T b|^2 + const, so it costs
    k^3 rather than p k^2."""
    forces = np.asarray(forces, float)
    target = forces.sum(axis=1)
    size = np.linalg.norm(target)
    if not size > 0:
        raise ValueError("forces: the elements' forces sum to zero; nothing to match")
    norms = np.linalg.norm(forces, axis=0)
    norms[norms == 0] = np.inf
    chosen, weights, missed = [], np.zeros(0), target
    gram, pull = np.zeros((0, 0)), np.zeros(0)
    while len(chosen) < min(most, forces.shape[1]):
        score = forces.T @ missed / norms
        score[chosen] = -np.inf
        j = int(np.argmax(score))
        column = forces[:, j]
        cross = forces[:, chosen].T @ column
        gram = np.block([[gram, cross[:, None]], [cross[None, :], column @ column]])
        pull = np.append(pull, column @ target)
        chosen.append(j)
        ridge = 1e-12 * np.trace(gram) / len(chosen)
        L = np.linalg.cholesky(gram + ridge * np.eye(len(chosen)))
        weights, _ = nnls(L.T, solve_triangular(L, pull, lower=True))
        missed = target - forces[:, chosen] @ weights
        if np.linalg.norm(missed) <= residual * size:
            break
    keep = weights > 0
    return (np.array(chosen, dtype=np.int64)[keep], weights[keep],
            float(np.linalg.norm(missed) / size))
