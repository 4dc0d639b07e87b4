"""What the assembly did, hole by hole, read from an episode recording the same way for a real
cell's log and a simulated one: the hole records of meta.json give which hole a cycle filled and
how it ended (the cell knows whether a journal seated); everything else comes from the signals
a real cell logs, the controller's wrench estimate (``O_F_ext_hat_K``) and the TCP from the
encoders (``O_T_EE``), never from simulator truth.

Per insertion (the ``insert`` phase of each cycle; a cycle starts at its ``locate`` phase):

| outcome | unit | from |
|---|---|---|
| seated | 1/0 | the hole record's outcome |
| seated_depth | mm | TCP descent over the insert phase (its start, a stated height over the hole as the cell sees it, to its height over the last 0.1 s): depth plus that height |
| peak_axial_force | N | largest upward wrench estimate after first contact |
| peak_lateral_force | N | largest horizontal wrench estimate after first contact |
| contact_to_seated | s | first contact to the TCP within :data:`SEATED_BAND_M` of its final height (seated holes) |
| misalignment_at_contact | mm | horizontal TCP offset at first contact from where the journal ended (seated holes: the bore's axis) |

First contact: the first sample after the phase's first 50 ms with an estimate above
:data:`~serpar.diagnosis.insertion_friction.CONTACT_N`, or with the tip at the bore's entry
(:data:`MEET_M` above the final height), whichever comes first: a journal that lands inside
the clearance meets the bore without a force the estimate resolves.
| chamfer_slide | 1/0 | a chamfer slide (diagnosis/insertion_friction.py) in the phase |
| jam | 1/0 | the hole record's outcome |

A value that does not apply (a hole
with no contact, the time to seat of a hole that did not) is NaN and left out of comparisons.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.insertion_friction import CONTACT_N, chamfer_slides, sigma_of_mean
from serpar.errors import ConfigError
from serpar.sim import channels as ch
from serpar.sim.recording import Recording, read_recording

Vec = NDArray[np.float64]

OUTCOMES: dict[str, str] = {
    "seated": "1", "seated_depth": "mm", "peak_axial_force": "N", "peak_lateral_force": "N",
    "contact_to_seated": "s", "misalignment_at_contact": "mm", "chamfer_slide": "1", "jam": "1",
}
"""Outcome name -> unit, in report order."""
RESOLUTION: dict[str, float] = {"contact_to_seated": 1e-3}
"""What an outcome is measured to: a time in samples of the 1 kHz log. A paired difference
within it is agreement, whatever the spread of the pairs (two holes 1 ms apart each have a
zero-width interval)."""
SEATED_BAND_M = 20e-6
"""[m] The TCP is seated once within this of its final height (the journal's last 0.02 mm)."""
SKIP_S = 0.05
"""[s] The start of an insert phase, where the estimate still carries the align move."""
TAIL_S = 0.1
MEET_M = 1.6e-3
"""[m] Tip height over its seated height at the top of the bore's entry chamfer: journal 1.5 mm,
entry chamfer 0.1 mm (sim/conductor.py, sim/baseplate.py)."""


BORE_M = (0.1e-3, 1.3e-3)
"""[m] Tip height over its seated height while the journal travels in the bore: below the
entry chamfer (1.4 mm and up), above the shoulder's landing."""
MIN_BORE_SAMPLES = 20


@dataclass(frozen=True)
class HoleOutcome:
    cycle: int
    hole: int | None
    values: dict[str, float]
    bore_axial: tuple[float, float] | None = None
    """A seated insertion's mean axial force while the journal travels in the bore [N] and its
    sigma (from the window's own scatter and correlation time): the bore's friction against
    the push (diagnosis/bore_friction.py); None where the travel was not seen."""


def _column(rec: Recording, name: str) -> Vec:
    return np.asarray(rec.signals.column(name), float)


def _cycles(rec: Recording) -> list[tuple[float, float] | None]:
    """Per cycle the (start, end) of its insert phase, None where it never got there."""
    out: list[tuple[float, float] | None] = []
    for p in rec.meta.phases:
        if p.name == "locate":
            out.append(None)
        elif p.name == "insert" and out:
            out[-1] = (p.start, p.end)
    return out


def _bore_axial(t: Vec, z: Vec, f: Vec, span: tuple[float, float]) -> tuple[float, float] | None:
    """The mean axial estimate over the in-bore travel of a seated insertion, and its sigma."""
    s = np.flatnonzero((t >= span[0]) & (t <= span[1]))
    if s.size < 10:
        return None
    z_end = float(z[s[t[s] >= t[s[-1]] - TAIL_S]].mean())
    h = z[s] - z_end
    inside = s[(h > BORE_M[0]) & (h < BORE_M[1])]
    if inside.size < MIN_BORE_SAMPLES:
        return None
    axial = f[inside, 2]
    dt = float(np.median(np.diff(t[s])))
    return float(axial.mean()), sigma_of_mean(axial, dt, inside.size * dt)


def _insertion(t: Vec, z: Vec, xy: Vec, f: Vec, span: tuple[float, float], seated: bool
               ) -> dict[str, float]:
    s = np.flatnonzero((t >= span[0]) & (t <= span[1]))
    nan = float("nan")
    out = dict.fromkeys(("seated_depth", "peak_axial_force", "peak_lateral_force",
                         "contact_to_seated", "misalignment_at_contact"), nan)
    if s.size < 10:
        return out
    tail = s[t[s] >= t[s[-1]] - TAIL_S]
    z_end, xy_end = float(z[tail].mean()), xy[tail].mean(axis=0)
    late = s[t[s] >= t[s[0]] + SKIP_S]
    touching = late[(np.linalg.norm(f[late], axis=1) > CONTACT_N) | (z[late] - z_end <= MEET_M)]
    if touching.size == 0:
        return out
    c = int(touching[0])
    after = s[s >= c]
    out.update(seated_depth=1e3 * (float(z[s[0]]) - z_end),
               peak_axial_force=float(f[after, 2].max()),
               peak_lateral_force=float(np.linalg.norm(f[after, :2], axis=1).max()))
    if seated:
        inside = after[z[after] - z_end < SEATED_BAND_M]
        out["contact_to_seated"] = float(t[inside[0]] - t[c]) if inside.size else nan
        out["misalignment_at_contact"] = 1e3 * float(np.linalg.norm(xy[c] - xy_end))
    return out


def hole_outcomes(folder: str | Path) -> list[HoleOutcome]:
    """One :class:`HoleOutcome` per hole record of an episode recording, in cycle order."""
    path = Path(folder)
    meta_file = path / "meta.json"
    if not meta_file.is_file():
        raise ConfigError(f"{path}: no meta.json (a serpar run --record episode folder)")
    holes = json.loads(meta_file.read_text()).get("holes")
    if not isinstance(holes, list):
        raise ConfigError(f"{meta_file}: no hole records ('holes'): a recording of an assembly "
                          "episode (serpar run --record) has one per hole")
    rec = read_recording(path)
    cols = set(rec.signals.column_names)
    need = [c for c in (*ch.F_EXT[:3], *ch.TCP_POSITION) if c not in cols]
    if need:
        raise ConfigError(f"{path}: no {', '.join(need)} channel(s): the outcomes need the wrench "
                          "estimate and the TCP position")
    t = _column(rec, ch.TIME)
    z = _column(rec, ch.TCP_POSITION[2])
    xy = np.stack([_column(rec, c) for c in ch.TCP_POSITION[:2]], axis=1)
    f = np.stack([_column(rec, c) for c in ch.F_EXT[:3]], axis=1)
    slides = chamfer_slides(rec)
    spans = _cycles(rec)
    out = []
    for record in holes:
        cycle = int(record["cycle"])
        seated = record.get("outcome") == "success"
        values = {"seated": float(seated), "jam": float(record.get("outcome") == "jam")}
        span = spans[cycle] if cycle < len(spans) else None
        bore = _bore_axial(t, z, f, span) if span is not None and seated else None
        if span is None:
            values |= dict.fromkeys(("seated_depth", "peak_axial_force", "peak_lateral_force",
                                     "contact_to_seated", "misalignment_at_contact",
                                     "chamfer_slide"), float("nan"))
        else:
            values |= _insertion(t, z, xy, f, span, seated)
            values["chamfer_slide"] = float(np.any((slides.time >= span[0]) & (slides.time <= span[1])))
        hole = record.get("hole")
        out.append(HoleOutcome(cycle, None if hole is None else int(hole),
                               {k: values[k] for k in OUTCOMES}, bore))
    return out
