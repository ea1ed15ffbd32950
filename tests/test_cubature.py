"""Cubature (anisofem.reduced.cubature): the greedy choice with non-negative least squares
finds a column that carries the whole sum, takes every column with weight 1 where nothing less
will do, stops at `most`, and refuses forces that sum to zero."""
import numpy as np
import pytest

from anisofem.reduced.cubature import select


def test_one_column_that_carries_the_sum_is_chosen_alone():
    """Columns a, b, a, b, a + b: their sum is 3 (a + b), the last column three times."""
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 40))
    chosen, weights, missed = select(np.column_stack([a, b, a, b, a + b]), 1e-9, 5)
    assert chosen.tolist() == [4]
    assert weights == pytest.approx([3.0], rel=1e-12)
    assert missed < 1e-12


def test_independent_columns_are_all_kept_with_weight_one():
    """Where no fewer columns span the sum (independent columns), every one is chosen and
    non-negative least squares finds the weights 1."""
    forces = np.random.default_rng(1).normal(size=(60, 12))
    chosen, weights, missed = select(forces, 1e-10, 12)
    assert sorted(chosen.tolist()) == list(range(12))
    assert np.abs(weights - 1.0).max() < 1e-8
    assert missed < 1e-10


def test_stops_at_most_and_says_what_it_missed():
    forces = np.random.default_rng(2).normal(size=(60, 12))
    chosen, weights, missed = select(forces, 1e-10, 5)
    assert len(chosen) <= 5 and (weights > 0).all()
    assert np.linalg.norm(forces[:, chosen] @ weights - forces.sum(axis=1)) == pytest.approx(
        missed * np.linalg.norm(forces.sum(axis=1)), rel=1e-9)
    assert missed > 0.1


def test_refuses_forces_that_sum_to_zero():
    with pytest.raises(ValueError, match="forces"):
        select(np.zeros((5, 3)), 0.01, 3)
