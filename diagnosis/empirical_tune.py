"""Refining a kept empirical group's continuous shape parameter (a transition speed, a Stribeck
velocity, a time constant): the library offers it on a grid; the data usually hold a value
between two grid points, and the grid's nearest leaves a share of the shape unexplained (a
Stribeck speed of 0.035 rad/s between the grid's 0.02 and 0.05 leaves a quarter of the fall)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from serpar.diagnosis.empirical_term import BasisGroup, Refit, Tuning, columns_at, design

Vec = NDArray[np.float64]
Rows = NDArray[np.int64]


def tune(groups: list[BasisGroup], refit: Refit, chosen: list[int], train: Rows, held: Rows,
         n_channels: int) -> list[int]:
    """``chosen`` with each group that has a :class:`Tuning` replaced by the same group at the
    value of its parameter that fits the training rows best, the others' contributions held
    (a Stribeck speed of 0.035 rad/s between the grid's 0.02 and 0.05 leaves a quarter of the
    fall). A refined group is appended to ``groups``; it replaces the grid's only where it
    also fits the held-out rows better, and the whole set only where the model refitted with
    it leaves less held-out residual."""
    r_t, r_h, coef = refit(chosen)
    edges = np.cumsum([0] + [groups[g].width for g in chosen])
    out = list(chosen)
    for i, g in enumerate(chosen):
        tuning = groups[g].tuning
        if tuning is None:
            continue
        c = coef[edges[i]:edges[i + 1]]
        # what is left for this group: the residual with its own contribution given back
        y_t = r_t + design(groups, [g], train, n_channels) @ c
        y_h = r_h + design(groups, [g], held, n_channels) @ c
        new = _refined(groups[g], tuning, y_t, train, n_channels)
        if _held_drop(new, y_t, y_h, train, held, n_channels) > _held_drop(
                groups[g], y_t, y_h, train, held, n_channels):
            groups.append(new)
            out[i] = len(groups) - 1
    if out == chosen:
        return chosen
    refined = refit(out)[1]
    return out if float(refined @ refined) < float(r_h @ r_h) else chosen


def _refined(group: BasisGroup, tuning: Tuning, y: Vec, rows: Rows, n_channels: int
             ) -> BasisGroup:
    """The group at the parameter value (log-uniform within the tuning's bounds) whose
    projection removes most of ``y`` (the whole whitened residual on ``rows``)."""
    target = _channel(group, y, n_channels)

    def left(log_value: float) -> float:
        x = columns_at(tuning.at(float(np.exp(log_value))), rows)
        coef, *_ = np.linalg.lstsq(x, target, rcond=None)
        return float(np.sum((target - x @ coef) ** 2))
    start = np.log(group.detail[tuning.name])
    lo, hi = np.log(tuning.low), np.log(tuning.high)
    # the grid's value bracketed by its neighbours' share of the range: the search refines,
    # it does not wander to another minimum the grid already tried
    best = minimize_scalar(left, bounds=(max(lo, start - 0.7), min(hi, start + 0.7)),
                           method="bounded", options={"xatol": 0.01})
    return tuning.at(float(np.exp(best.x))) if best.fun < left(start) else group


def _channel(group: BasisGroup, y: Vec, n_channels: int) -> Vec:
    return y.reshape(-1, n_channels)[:, group.column] if group.column is not None else y


def _held_drop(group: BasisGroup, y_t: Vec, y_h: Vec, train: Rows, held: Rows,
               n_channels: int) -> float:
    """Held-out chi-square removed by the group fitted to ``y_t`` on the training rows."""
    t, h = _channel(group, y_t, n_channels), _channel(group, y_h, n_channels)
    coef, *_ = np.linalg.lstsq(columns_at(group, train), t, rcond=None)
    fit = columns_at(group, held) @ coef
    return float(2 * h @ fit - fit @ fit)


__all__ = ["tune"]
