"""Seed 000 Table 2 joint coordinates (assets/stewart/joints.csv) and the geometry built on them,
and Table 5's identified platform errors.

Kept apart from :mod:`serpar.sim.stewart` (the MuJoCo model) so that kinematics-only users need no
model code; serpar.sim.stewart re-exports :func:`load_joint_table`.
"""

from __future__ import annotations

import csv
from functools import lru_cache

import numpy as np

from serpar.assets import asset_path
from serpar.errors import ConfigError
from serpar.kinematics.stewart_kinematics import N_LEGS, StewartGeometry


@lru_cache(maxsize=1)
def _read_joint_table() -> tuple[tuple[float, ...], ...]:
    with asset_path("stewart", "joints.csv").open(newline="") as f:
        rows = sorted(csv.DictReader(f), key=lambda r: int(r["leg"]))
    if [int(r["leg"]) for r in rows] != list(range(1, N_LEGS + 1)):
        raise ConfigError("assets/stewart/joints.csv must list legs 1..6 exactly once")
    keys = ("px_mm", "py_mm", "bx_mm", "by_mm", "bz_mm")
    return tuple(tuple(float(r[k]) for k in keys) for r in rows)


def load_joint_table(swap_legs12: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(P, B): 6x3 platform joints in the platform frame (z = 0) and base joints, in metres.

    The CSV's pz (245 mm) is the Table 2 platform height, not part of the platform frame.
    swap_legs12 exchanges the platform/base xy of legs 1 and 2: Table 2 as printed is
    architecture-singular (see assets/stewart/README.md).
    """
    t = np.array(_read_joint_table()) * 1e-3  # mm -> m
    p = np.column_stack([t[:, 0], t[:, 1], np.zeros(N_LEGS)])
    b = t[:, 2:5].copy()
    if swap_legs12:
        p[:2, :2], b[:2, :2] = b[:2, :2].copy(), p[:2, :2].copy()
    return p, b


@lru_cache(maxsize=16)  # cheap to build, but stroke_for_pose may run in step loops
def table_geometry(swap_legs12: bool, l_min: float, stroke: float, lower_deg: float,
                   upper_deg: float, home_z: float) -> StewartGeometry:
    """StewartGeometry from Table 2 with the given leg, limit and home parameters (SI, deg)."""
    p, b = load_joint_table(swap_legs12)
    return StewartGeometry(p, b, l_min, stroke, lower_deg, upper_deg, (0.0, 0.0, home_z))


def table5_errors() -> np.ndarray:
    """(6, 7) seed 000 Table 5 errors in metres: per leg dl, dP xyz, dB xyz (the real cell's
    identified platform errors, assets/stewart/table5_errors.csv)."""
    rows = np.loadtxt(asset_path("stewart", "table5_errors.csv"), delimiter=",", comments="#", skiprows=3)
    return rows[:, 1:] * 1e-3
