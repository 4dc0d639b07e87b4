"""``serpar blind-bench``: random concealed effect (or none) and magnitude per trial, make the
twin, diagnose it without the answer, score.

Scores (issue 7 targets): the top-ranked effect is the hidden one (>= 90 % of trials with an
effect); "no missing physics" on effect-free trials (>= 95 %); held-out whitened RMS after
the fit over the noise floor (1 for whitened residuals; target <= 1.5); diagnosis wall time
(<= 2 min). A trial that raises is recorded with its error and scored as a miss.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from serpar.diagnosis.choose import family_from_recording
from serpar.diagnosis.select import diagnose
from serpar.errors import ConfigError
from serpar.twins.registry import DOMAINS, domain_module, magnitude_range, make_twin

RMS_TARGET = 1.5


@dataclass(frozen=True)
class Trial:
    index: int
    seed: int
    domain: str
    effect: str
    magnitude: float
    top_effect: str | None
    verdict: str
    correct: bool
    heldout_rms_ratio: float
    diagnosis_s: float
    error: str | None = None

    def as_dict(self) -> dict[str, object]:
        return dict(self.__dict__)


def plan(trials: int, seed: int, domains: tuple[str, ...]) -> list[tuple[str, str, float, int]]:
    """(domain, effect or 'none', magnitude, twin seed) per trial: effects in equal shares,
    with 'none' as one more choice per domain."""
    if trials < 1:
        raise ConfigError(f"--trials must be >= 1, got {trials}")
    bad = [d for d in domains if d not in DOMAINS]
    if bad:
        raise ConfigError(f"unknown domain(s) {bad}; valid: {', '.join(DOMAINS)}")
    choices = [(d, e) for d in domains for e in ("none", *domain_module(d).EFFECTS)]
    rng = np.random.default_rng([seed, 77])
    out = []
    for k in range(trials):
        d, e = choices[int(rng.integers(len(choices)))]
        lo, hi = magnitude_range(e, d) if e != "none" else (0.0, 0.0)
        out.append((d, e, float(rng.uniform(lo, hi)), int(rng.integers(1_000_000)) + k))
    return out


def run_trial(index: int, domain: str, effect: str, magnitude: float, seed: int) -> Trial:
    try:
        rec, _answer = make_twin(None if effect == "none" else effect,
                                 magnitude if effect != "none" else None, seed, domain)
        t0 = time.perf_counter()
        diag = diagnose(family_from_recording(rec), seed)
        wall = time.perf_counter() - t0
    except Exception as exc:  # noqa: BLE001 (one failing trial never kills the bench)
        return Trial(index, seed, domain, effect, magnitude, None, "", False, float("nan"),
                     float("nan"), f"{type(exc).__name__}: {exc}")
    correct = diag.no_missing_physics if effect == "none" else diag.top_effect == effect
    return Trial(index, seed, domain, effect, magnitude, diag.top_effect, diag.verdict,
                 bool(correct), diag.heldout_rms_after, wall)


def summarise(trials: list[Trial]) -> dict[str, object]:
    with_effect = [t for t in trials if t.effect != "none"]
    none = [t for t in trials if t.effect == "none"]
    ratios = np.array([t.heldout_rms_ratio for t in trials if np.isfinite(t.heldout_rms_ratio)])
    walls = np.array([t.diagnosis_s for t in trials if np.isfinite(t.diagnosis_s)])
    per_effect: dict[str, dict[str, object]] = {}
    for t in trials:
        e = per_effect.setdefault(t.effect, {"trials": 0, "correct": 0, "rms_ratios": []})
        e["trials"] += 1  # type: ignore[operator]
        e["correct"] += int(t.correct)  # type: ignore[operator]
        e["rms_ratios"].append(t.heldout_rms_ratio)  # type: ignore[union-attr]

    def share(ts: list[Trial]) -> float | None:
        return float(np.mean([t.correct for t in ts])) if ts else None

    return {
        "trials": len(trials), "errors": sum(t.error is not None for t in trials),
        "top_effect_correct": share(with_effect), "no_missing_physics_on_none": share(none),
        "heldout_rms_ratio_median": float(np.median(ratios)) if ratios.size else None,
        "heldout_rms_ratio_max": float(ratios.max()) if ratios.size else None,
        "heldout_rms_within_target": float(np.mean(ratios <= RMS_TARGET)) if ratios.size else None,
        "diagnosis_s_median": float(np.median(walls)) if walls.size else None,
        "diagnosis_s_max": float(walls.max()) if walls.size else None,
        "per_effect": per_effect,
    }


def blind_bench(trials: int, seed: int, domains: tuple[str, ...] = tuple(DOMAINS),
                progress: Callable[[Trial], object] | None = None) -> list[Trial]:
    out = []
    for k, (d, e, mag, s) in enumerate(plan(trials, seed, domains)):
        out.append(run_trial(k, d, e, mag, s))
        if progress is not None:
            progress(out[-1])
    return out
