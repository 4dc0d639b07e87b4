"""Shared pieces of the arm calibration tests (MD-H and POE forms)."""

from __future__ import annotations

import numpy as np

from sim.arm import Q_MAX, Q_MIN

TOOL = (0.01, 0.05, 0.12)
LO, HI = np.asarray(Q_MIN) + 0.1, np.asarray(Q_MAX) - 0.1


def poses(n: int, seed: int) -> np.ndarray:
    """Random joint angles 0.1 rad inside the limits."""
    return np.random.default_rng(seed).uniform(LO, HI, size=(n, 7))


def gravity_like_load(q: np.ndarray) -> np.ndarray:
    """A smooth configuration-dependent load of the size of the Panda's gravity torques,
    zero on joint 1 as for a level base."""
    return np.column_stack([np.zeros(len(q)), 40 * np.sin(q[:, 1]), 5 * np.cos(q[:, 2]),
                            20 * np.sin(q[:, 3]), 2 * np.sin(q[:, 4]), 3 * np.cos(q[:, 5]),
                            0.5 * np.sin(q[:, 6])])
