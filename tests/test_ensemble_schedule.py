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
