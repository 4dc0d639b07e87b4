"""The spec's conversions on the source's samples, before the plausibility checks: ``scale``
(a multiplier per channel, source column, matrix source or channel family) and ``joint_map``
(motor side to joint side). Motor-side angles of 70 rad are legitimate here; only the joint
side they become must look like a robot's."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError
from serpar.sim.channels import numbered
from serpar.sim.importers.spec import ANGLE, FAMILY_KIND, TORQUE, ImportSpec, compact

POWER_TOLERANCE = 1e-9
"""max |T^T A - I| below this: the torque map conserves power."""


def _scale_targets(key: str, mapping: dict[str, str]) -> list[str]:
    """The channels a scale key names: a channel, its source column, a matrix source
    (``tau`` for tau.1..tau.7) or a family (``tau_drive`` for tau_drive1..)."""
    family = re.compile(re.escape(key) + r"[0-9]+")
    return [chan for chan, col in mapping.items()
            if key in (chan, col) or family.fullmatch(chan)
            or (col.startswith(key + ".") and col[len(key) + 1:].isdigit())]


def scale(arrays: dict[str, NDArray], mapping: dict[str, str], spec: ImportSpec
          ) -> tuple[dict[str, NDArray], list[str]]:
    where = Path(spec.path).name
    done: dict[str, str] = {}
    for key, factor in spec.scale.items():
        targets = _scale_targets(key, mapping)
        if not targets:
            imported = ", ".join(f"{col} ({chan})" for chan, col in mapping.items())
            raise ConfigError(f"{where}: scale: {key!r} names no imported channel or source "
                              f"column; imported: {imported}")
        for chan in targets:
            if chan in done:
                raise ConfigError(f"{where}: scale: {chan} is scaled twice ({done[chan]!r} and "
                                  f"{key!r}); give one")
            if arrays[chan].dtype == object:
                raise ConfigError(f"{where}: scale: {chan} is text, not a number")
            done[chan] = key
            arrays[chan] = arrays[chan] * factor
    notes = [f"scaled: {compact(targets)} x {factor:g}" for key, factor in spec.scale.items()
             if (targets := _scale_targets(key, mapping))]
    return arrays, notes


def joint_side(arrays: dict[str, NDArray], spec: ImportSpec
               ) -> tuple[dict[str, NDArray], dict[str, str], list[str]]:
    """(arrays with the motor-side families replaced by the joint side, {motor-side name:
    joint-side name}, notes)."""
    jm = spec.joint_map
    if jm is None:
        return arrays, {}, []
    where, n = Path(spec.path).name, jm.n
    imported = [c for c in arrays if c != "time"]
    sources = {src: numbered(src, n) for src in jm.sources}
    for src, names in sources.items():
        missing = [c for c in names if c not in arrays]
        if missing:
            raise ConfigError(f"{where}: joint_map: from {src}: {compact(missing)} not imported "
                              f"(a {n}-joint map needs {src}1..{src}{n}); imported: "
                              f"{compact(imported)}")
        if f"{src}{n + 1}" in arrays:
            raise ConfigError(f"{where}: joint_map: {src}{n + 1} is imported but the map has "
                              f"{n} joints: it would stay motor-side")
    motor = {src: np.stack([arrays.pop(c) for c in names]) for src, names in sources.items()}
    renames: dict[str, str] = {}
    notes = []
    for src, dst in zip(jm.sources, jm.to, strict=True):
        kind = FAMILY_KIND[dst]
        joint = (jm.t if kind == TORQUE else jm.a) @ motor[src]
        if kind == ANGLE:
            joint = joint + jm.offset[:, None]
        targets = numbered(dst, n)
        clash = [c for c in targets if c in arrays]
        if clash:
            raise ConfigError(f"{where}: joint_map: {compact(clash)} imported and mapped from "
                              f"{src} too; drop one")
        arrays.update(zip(targets, joint, strict=True))
        renames.update(zip(sources[src], targets, strict=True))
        how = ("A theta_m + offsets" if kind == ANGLE else "A dtheta_m" if kind != TORQUE
               else "T tau_m, T = inv(A).T (power-conserving)" if jm.torque_matrix is None
               else "T tau_m, T = joint_map.torque_matrix")
        notes.append(f"joint map ({where}): {compact(targets)} = {how}, from the motor-side "
                     f"{compact(sources[src])}")
    if jm.torque_matrix is not None and jm.power_error() > POWER_TOLERANCE:
        notes.append(f"joint map: torque_matrix is not inv(A).T (max |T^T A - I| = "
                     f"{jm.power_error():.3g}): tau . dq differs from tau_m . dtheta_m")
    return arrays, renames, notes
