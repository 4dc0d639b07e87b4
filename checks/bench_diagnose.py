"""``serpar bench --diagnose``: the arm-dynamics diagnosis with its full candidate library on
a 60-s recording of the Panda with a mix of concealed effects (``serpar twin --domain
arm_dynamics --duration 60 --effect mix --seed 0``: 7 joints at 1 kHz), timed end to end
(the twin's own simulation apart), and whether it named what the twin concealed."""

from __future__ import annotations

import time
from collections.abc import Callable

from serpar.diagnosis.choose import family_from_recording
from serpar.diagnosis.select import diagnose
from serpar.twins.arm_dynamics_twin import MIX, make_twin

DURATION_S = 60.0
SEED = 0
GOAL_S = 120.0
"""The diagnosis' wall time goal on a 2-core machine [s]."""


def diagnose_bench(tick: Callable[[str], None] | None = None) -> dict[str, object]:
    t0 = time.perf_counter()
    rec, answer = make_twin(MIX, None, SEED, duration=DURATION_S)
    twin_s = time.perf_counter() - t0
    if tick:
        tick("diagnose: twin")
    t0 = time.perf_counter()
    family = family_from_recording(rec)
    d = diagnose(family, SEED)
    wall = time.perf_counter() - t0
    if tick:
        tick("diagnose: diagnosis")
    concealed = [str(p["effect"]) for p in answer["effects"]]  # type: ignore[union-attr]
    established = [f.effect for f in d.established]
    return {"recording": f"serpar twin --domain arm_dynamics --duration {DURATION_S:g} "
                         f"--effect mix --seed {SEED}",
            "twin_s": twin_s, "diagnosis_s": wall, "candidates": len(family.effects),
            "concealed": concealed, "established": established,
            "suspected": [f.effect for f in d.suspected],
            "named_right": sorted(established) == sorted(concealed),
            "heldout_rms_after": d.heldout_rms_after, "verdict": d.verdict}
