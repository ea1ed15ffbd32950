import os

import numpy as np
import pytest

import anisofem as af

try:
    import torch
except ImportError:
    torch = None
else:
    # torch's OpenMP threads spin-wait: next to any other load they slow these small models'
    # steps many times over, and one thread is as fast on them when the machine is idle. The
    # processes tests start get one thread too, so that they train what this one trains.
    torch.set_num_threads(1)
    os.environ.setdefault("OMP_NUM_THREADS", "1")


@pytest.fixture(autouse=True)
def one_torch_thread():
    """Every test starts with torch on one thread: some sequences of earlier tests leave it on
    two (numba's and torch's OpenMP share libgomp), and a training resumed in this process must
    sum in the order of the one-thread process it continues."""
    if torch is not None:
        torch.set_num_threads(1)


@pytest.fixture(scope="session")
def beam():
    """The paper-sized cantilever: 0.1 x 0.02 x 0.02 m, 200 tets."""
    return af.box_beam(cells=(10, 2, 2))


def mirror_partner(X, axis):
    """Index of each vertex's mirror image across the plane X[axis] = 0."""
    Y = X.copy()
    Y[:, axis] *= -1
    d = np.linalg.norm(X[:, None] - Y[None], axis=-1)
    j = d.argmin(axis=1)
    assert d[np.arange(len(X)), j].max() < 1e-12
    return j
