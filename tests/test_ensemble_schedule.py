"""Scheduling ensemble members (jrigid.ensemble.schedule): lockstep efficiency by hand."""

from __future__ import annotations

import numpy as np
import pytest

from jrigid import ensemble
from jrigid.ensemble import schedule


def test_lockstep_efficiency_by_hand():
    steps = np.array([1, 10, 1, 10])
    assert float(schedule.lockstep_efficiency(steps, 2)) == pytest.approx(22 / 40)
    order = schedule.difficulty_order(steps)
    assert float(schedule.lockstep_efficiency(steps, 2, order)) == pytest.approx(1.0)
    # a padded last chunk counts only its members
    assert float(schedule.lockstep_efficiency(np.array([4, 2, 3]), 2)) == pytest.approx(9 / 11)


def test_difficulty_order_is_stable_and_exported():
    order = ensemble.difficulty_order(np.array([3.0, 1.0, 3.0, 1.0]))
    np.testing.assert_array_equal(np.asarray(order), [1, 3, 0, 2])
    assert ensemble.lockstep_efficiency is schedule.lockstep_efficiency


@pytest.mark.parametrize("order", [[0, 0, 0, 0], [0, 1], [[0, 1], [2, 3]]])
def test_lockstep_efficiency_refuses_an_order_that_is_not_a_permutation(order):
    """A repeated index gave an efficiency of 1.0, a short order 0.55."""
    with pytest.raises(ValueError, match="permutation of range"):
        schedule.lockstep_efficiency(np.array([1, 10, 1, 10]), 2, order)


@pytest.mark.parametrize("chunk_size", [0, -1, 2.0, True])
def test_lockstep_efficiency_refuses_a_bad_chunk_size(chunk_size):
    with pytest.raises(ValueError, match="chunk_size must be a positive int"):
        schedule.lockstep_efficiency(np.array([1, 10, 1, 10]), chunk_size)
    assert float(schedule.lockstep_efficiency(np.array([1, 10, 1, 10]), np.int64(2))) == \
        pytest.approx(22 / 40)


def test_difficulty_order_needs_one_number_per_member():
    with pytest.raises(ValueError, match=r"\(N,\)"):
        schedule.difficulty_order(np.ones((2, 3)))


def test_lockstep_efficiency_of_members_that_took_no_step_is_one():
    """All-zero step counts gave 0/0 = NaN, outside the documented (0, 1]."""
    assert float(schedule.lockstep_efficiency(np.array([0, 0, 0]), 2)) == 1.0
