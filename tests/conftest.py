import numpy as np
import pytest

import anisofem as af


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
