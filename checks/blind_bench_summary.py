"""The blind bench's scores (checks/blind_bench.py runs the trials): per kind of trial the
share right against its target, the wrong findings, the held-out figures."""

from __future__ import annotations

import numpy as np

from serpar.checks.blind_bench import KINDS, RMS_TARGET, WRONG, Trial

TARGETS = {"effect": 0.9, "outside": 0.8, "none": 0.95, "wrong_sigma": 0.9}
"""Share of each kind's trials that must be right."""


def summarise(trials: list[Trial]) -> dict[str, object]:
    ratios = np.array([t.heldout_rms_ratio for t in trials if np.isfinite(t.heldout_rms_ratio)
                       and t.kind not in ("wrong_sigma", "outside")])
    walls = np.array([t.diagnosis_s for t in trials if np.isfinite(t.diagnosis_s)])
    per_effect: dict[str, dict[str, object]] = {}
    for t in trials:
        key = t.effect if t.kind != "wrong_sigma" else WRONG
        e = per_effect.setdefault(key, {"trials": 0, "correct": 0, "rms_ratios": []})
        e["trials"] += 1  # type: ignore[operator]
        e["correct"] += int(t.correct)  # type: ignore[operator]
        e["rms_ratios"].append(t.heldout_rms_ratio)  # type: ignore[union-attr]

    def share(ts: list[Trial]) -> float | None:
        decided = [t.correct for t in ts if not t.undecided]
        return float(np.mean(decided)) if decided else None

    rows = {}
    for kind, words in KINDS.items():
        ts = [t for t in trials if t.kind == kind]
        r = np.array([t.heldout_rms_ratio for t in ts if np.isfinite(t.heldout_rms_ratio)])
        rows[kind] = {"what": words, "trials": len(ts), "correct": share(ts), "target": TARGETS[kind],
                      "a_or_b": sum(t.undecided for t in ts),
                      "wrong_findings_established": sum(t.wrong_finding for t in ts),
                      "heldout_rms_median": float(np.median(r)) if r.size else None,
                      "heldout_rms_max": float(r.max()) if r.size else None}
        if kind == "outside":
            e = np.array([t.empirical_rms for t in ts if t.empirical_rms is not None])
            rows[kind]["heldout_rms_with_empirical_median"] = float(np.median(e)) if e.size else None
            rows[kind]["heldout_rms_with_empirical_within_target"] = (
                float(np.mean(e <= RMS_TARGET)) if e.size else None)
    return {
        "trials": len(trials), "errors": sum(t.error is not None for t in trials),
        "rows": rows,
        "top_effect_correct": rows["effect"]["correct"],
        "outside_characterised": rows["outside"]["correct"],
        "nothing_established_on_none": rows["none"]["correct"],
        "wrong_sigma_detected": rows["wrong_sigma"]["correct"],
        "wrong_findings_established": sum(t.wrong_finding for t in trials),
        "heldout_rms_ratio_median": float(np.median(ratios)) if ratios.size else None,
        "heldout_rms_ratio_max": float(ratios.max()) if ratios.size else None,
        "heldout_rms_within_target": float(np.mean(ratios <= RMS_TARGET)) if ratios.size else None,
        "diagnosis_s_median": float(np.median(walls)) if walls.size else None,
        "diagnosis_s_max": float(walls.max()) if walls.size else None,
        "per_effect": per_effect,
    }
