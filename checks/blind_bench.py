"""``serpar blind-bench``: random concealed effect (or none) and magnitude per trial, make the
twin, diagnose it without the answer, score.

Four kinds of trial: a hidden effect of the candidate library (it must be established, after
nothing but library effects that express part of its physics: joint friction before Stribeck
friction's fall; target >= 90 %); a hidden effect outside the library (a twin module's
``OUT_OF_LIBRARY``, or one of its ``WITHHELD`` effects with that candidate taken out of the
library for the trial: the empirical term must name its channel and variable, target >= 80 %,
with a held-out RMS <= 1.5 x noise after it); no effect (nothing may be established; >= 95 %);
and no effect in a recording that states its noise WRONG_SIGMA times too small (nothing
established, and the residual check must call the stated sigma optimistic; >= 90 %). On every
trial an established finding that is neither the hidden effect nor a library effect that
expresses part of the same physics (the twin module's ``PARTLY_IN_LIBRARY``, e.g. the Coulomb
part of Stribeck friction) counts as a wrong finding (target: none). Held-out whitened RMS
after the fit (1 = noise; target <= 1.5 where sigma is stated right) and the diagnosis wall
time are reported. A trial that raises is recorded with its error and scored as a miss. A
hidden effect the diagnosis reports as one side of "A or B: these data cannot tell" is neither
right nor wrong: counted (``a_or_b``) and left out of its kind's share.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass

import numpy as np

from serpar.diagnosis.choose import family_from_recording
from serpar.diagnosis.select import diagnose
from serpar.errors import ConfigError
from serpar.sim.robot_file import load_robot
from serpar.tasks.worker_life import end_with_parent
from serpar.twins.registry import ANY_ARM, DOMAINS, domain_module, magnitude_range, make_twin

RMS_TARGET = 1.5
WRONG_SIGMA = 2.0
"""Effect-free trials whose recording states its noise this many times too small."""


@dataclass(frozen=True)
class Trial:
    index: int
    seed: int
    domain: str
    effect: str
    magnitude: float
    top_effect: str | None
    """The first established finding."""
    verdict: str
    correct: bool
    heldout_rms_ratio: float
    diagnosis_s: float
    error: str | None = None
    sigma_error: float = 1.0
    """The recording states its noise this many times too small (1: stated correctly)."""
    established: tuple[str, ...] = ()
    suspected: tuple[str, ...] = ()
    noise_ratio: float | None = None
    """The data's noise over the stated sigma, as the diagnosis estimated it."""
    outside: bool = False
    """The hidden effect lies outside the candidate library (or its candidate was withheld)."""
    acceptable: tuple[str, ...] = ()
    """Library effects that express part of the hidden effect's physics."""
    characterised: tuple[str, ...] = ()
    """The empirical term's groups as "channel / variable / shape", first entered first."""
    empirical_rms: float | None = None
    """Held-out whitened RMS with the empirical term (None: no term)."""
    undecided: bool = False
    """The hidden effect is one side of an "A or B: these data cannot tell" finding: neither
    right nor wrong (left out of its kind's share)."""

    @property
    def kind(self) -> str:
        if self.effect != "none":
            return "outside" if self.outside else "effect"
        return "wrong_sigma" if self.sigma_error != 1.0 else "none"

    @property
    def wrong_finding(self) -> bool:
        """An established finding that is neither the hidden effect nor part of its physics."""
        return any(e != self.effect and e not in self.acceptable for e in self.established)

    def as_dict(self) -> dict[str, object]:
        return {**self.__dict__, "kind": self.kind, "wrong_finding": self.wrong_finding}


WRONG = "none, stated sigma wrong"
WITHHELD = " (candidate withheld)"
"""Suffix of a trial's effect whose candidate the diagnosis is run without."""


def plan(trials: int, seed: int, domains: tuple[str, ...], library_only: bool = False,
         kinds: tuple[str, ...] | None = None) -> list[tuple[str, str, float, int]]:
    """(domain, effect, 'none' or WRONG, magnitude, twin seed) per trial: effects in equal
    shares, with 'none' and an effect-free recording that states its noise WRONG_SIGMA times
    too small as two more choices per domain. ``kinds``: draw only trials of these kinds (of
    :data:`KINDS`); ``library_only``: the kinds "effect", "none" and "wrong_sigma" (no effect
    outside the candidate library, none with its candidate withheld)."""
    if trials < 1:
        raise ConfigError(f"--trials must be >= 1, got {trials}")
    bad = [d for d in domains if d not in DOMAINS]
    if bad:
        raise ConfigError(f"unknown domain(s) {bad}; valid: {', '.join(DOMAINS)}")
    if library_only:
        kinds = tuple(k for k in (kinds or tuple(KINDS)) if k != "outside")
    unknown = [k for k in kinds or () if k not in KINDS]
    if unknown:
        raise ConfigError(f"unknown trial kind(s) {unknown}; valid: {', '.join(KINDS)}")

    def kind(d: str, e: str) -> str:
        module = domain_module(d)
        if e in ("none", WRONG):
            return "none" if e == "none" else "wrong_sigma"
        outside = e.endswith(WITHHELD) or e in getattr(module, "OUT_OF_LIBRARY", ())
        return "outside" if outside else "effect"

    choices = [(d, e) for d in domains
               for e in ("none", WRONG, *domain_module(d).EFFECTS,
                         *(w + WITHHELD for w in getattr(domain_module(d), "WITHHELD", ())))
               if kinds is None or kind(d, e) in kinds]
    if not choices:
        raise ConfigError(f"no trial of kind(s) {', '.join(kinds or ())} in domain(s) "
                          f"{', '.join(domains)}")
    rng = np.random.default_rng([seed, 77])
    out = []
    for k in range(trials):
        d, e = choices[int(rng.integers(len(choices)))]
        lo, hi = (magnitude_range(e.removesuffix(WITHHELD), d) if e not in ("none", WRONG)
                  else (0.0, 0.0))
        out.append((d, e, float(rng.uniform(lo, hi)), int(rng.integers(1_000_000)) + k))
    return out


def _failed(index: int, domain: str, effect: str, magnitude: float, seed: int,
            exc: BaseException) -> Trial:
    """The record of a trial that raised: scored as a miss, its error kept."""
    label = "none" if effect in ("none", WRONG) else effect
    return Trial(index, seed, domain, label, magnitude, None, "", False, float("nan"),
                 float("nan"), f"{type(exc).__name__}: {exc}",
                 WRONG_SIGMA if effect == WRONG else 1.0)


def run_trial(index: int, domain: str, effect: str, magnitude: float, seed: int,
              robot: str | None = None) -> Trial:
    """One trial; ``robot``: the arm's URDF/MJCF file (the arm-dynamics twin on that arm,
    diagnosed with it; None: the Panda)."""
    withheld = effect.endswith(WITHHELD)
    hidden = None if effect in ("none", WRONG) else effect.removesuffix(WITHHELD)
    sigma_error = WRONG_SIGMA if effect == WRONG else 1.0
    label = "none" if hidden is None else effect
    try:
        rec, answer = make_twin(hidden, magnitude if hidden else None, seed, domain, sigma_error,
                                robot)
        t0 = time.perf_counter()
        family = family_from_recording(rec, load_robot(robot))
        if withheld:  # the library as it would be without this candidate
            family.effects = tuple(e for e in family.effects if e.name != hidden)
        diag = diagnose(family, seed)
        wall = time.perf_counter() - t0
    except Exception as exc:  # noqa: BLE001 (one failing trial never kills the bench)
        return _failed(index, domain, effect, magnitude, seed, exc)
    established = tuple(f.effect for f in diag.established)
    check = diag.residual
    ratio = None if check is None else check.noise_ratio
    module = domain_module(domain)
    outside = withheld or hidden in getattr(module, "OUT_OF_LIBRARY", ())
    acceptable = tuple(getattr(module, "PARTLY_IN_LIBRARY", {}).get(hidden, ()))
    emp = diag.empirical
    terms = emp.terms if emp is not None else ()
    characterised = tuple(f"{t.group.channel} / {t.group.variable} / {t.group.shape}" for t in terms)
    emp_rms = emp.heldout_rms_after if terms else None
    if outside:
        sig = answer.get("signature", {})
        first = terms[0].group if terms else None
        correct = (first is not None and first.channel in sig.get("channels", ())
                   and first.variable in sig.get("variables", ())
                   and all(e in acceptable for e in established))
    elif hidden is not None:  # established, after nothing but parts of its own physics
        correct = (hidden in established
                   and all(e in acceptable for e in established[:established.index(hidden)]))
    elif sigma_error == 1.0:
        correct = not established
    else:  # nothing found, and the stated sigma called optimistic by the data's own noise
        correct = (not established and ratio is not None and check is not None
                   and check.structured is False and ratio >= 0.75 * sigma_error)
    return Trial(index, seed, domain, label, magnitude, diag.top_effect, diag.verdict,
                 bool(correct), diag.heldout_rms_after, wall, None, sigma_error, established,
                 tuple(f.effect for f in diag.suspected), ratio, outside, acceptable,
                 characterised, emp_rms,
                 undecided=(hidden is not None and not outside and not correct
                            and _a_or_b_holds(diag.suspected, hidden)))


def _a_or_b_holds(suspected: tuple, hidden: str) -> bool:
    """Whether an "A or B: these data cannot tell" finding names ``hidden`` as A or B."""
    return any("these data cannot tell" in r and (f.effect == hidden or f" or {hidden} (" in r)
               for f in suspected for r in f.reasons)


KINDS = {"effect": "hidden effect in the library: established, after nothing but parts of its "
                   "own physics",
         "outside": "hidden effect outside the library: the empirical term's first group on "
                    "the right channel and variable, nothing else established",
         "none": "no effect: nothing established",
         "wrong_sigma": f"no effect, stated sigma {WRONG_SIGMA:g}x too small: nothing "
                        "established and the stated sigma called optimistic"}


def check_robot(domains: tuple[str, ...], robot: str | None) -> None:
    """One line, before any trial, for a robot file with a domain that takes none (or a file
    that is not an arm)."""
    if robot is None:
        return
    other = [d for d in domains if d != ANY_ARM]
    if other:
        raise ConfigError(f"--robot is for the {ANY_ARM} domain only; drop --domain "
                          f"{', '.join(other)} (the other domains are the Panda cell's)")
    load_robot(robot)


def blind_bench(trials: int, seed: int, domains: tuple[str, ...] = tuple(DOMAINS),
                progress: Callable[[Trial], object] | None = None,
                library_only: bool = False, kinds: tuple[str, ...] | None = None,
                robot: str | None = None, workers: int = 1) -> list[Trial]:
    """``robot``: every trial's arm, from its URDF/MJCF file (the arm-dynamics domain only);
    ``workers``: trials run at once, each in its own process (the trials are the same)."""
    check_robot(domains, robot)
    if workers < 1:
        raise ConfigError(f"--workers {workers}: must be >= 1")
    drawn = plan(trials, seed, domains, library_only, kinds)
    out: list[Trial] = []
    if workers == 1:
        for k, (d, e, mag, s) in enumerate(drawn):
            out.append(run_trial(k, d, e, mag, s, robot))
            if progress is not None:
                progress(out[-1])
        return out
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                             initializer=end_with_parent, initargs=(os.getpid(),)) as pool:
        futures = {pool.submit(run_trial, k, d, e, mag, s, robot): (k, d, e, mag, s)
                   for k, (d, e, mag, s) in enumerate(drawn)}
        for done in as_completed(futures):
            try:
                trial = done.result()
            except Exception as exc:  # noqa: BLE001 (a worker lost: that trial, not the bench)
                trial = _failed(*futures[done], exc)
            out.append(trial)
            if progress is not None:
                progress(trial)
    return sorted(out, key=lambda t: t.index)
