"""The answer of a diagnosis, as frozen data (``as_dict`` for ``--json``) and in words."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from serpar.diagnosis.empirical import EmpiricalTerm
from serpar.diagnosis.family import LocateRow
from serpar.diagnosis.residual import ResidualCheck
from serpar.diagnosis.units import PhysicalResidual

NO_MISSING_PHYSICS = "no missing physics found beyond noise"


@dataclass(frozen=True)
class ParamEstimate:
    name: str
    value: float
    std: float
    unit: str

    def words(self) -> str:
        return f"{self.name} = {self.value:.3g} ± {self.std:.2g} {self.unit}".rstrip()

    def as_dict(self) -> dict[str, object]:
        return {"name": self.name, "value": self.value, "std": self.std, "unit": self.unit}


@dataclass(frozen=True)
class CandidateScore:
    """One candidate fitted on top of the model of one selection step."""

    step: int
    effect: str
    n_params: int
    delta_bic_train: float
    """BIC change on the training rows (negative: better)."""
    delta_chi2_heldout: float
    """Held-out chi-square drop (positive: better)."""
    heldout_rms: float
    earns: bool
    """Both the training and the held-out criterion of :mod:`serpar.diagnosis.select`."""

    def as_dict(self) -> dict[str, object]:
        return {"step": self.step, "effect": self.effect, "n_params": self.n_params,
                "delta_bic_train": self.delta_bic_train,
                "delta_chi2_heldout": self.delta_chi2_heldout,
                "heldout_rms_whitened": self.heldout_rms, "earns": self.earns}


@dataclass(frozen=True)
class Finding:
    """An effect the selection kept, in the order it was added (rank 1 first)."""

    rank: int
    effect: str
    summary: str
    params: tuple[ParamEstimate, ...]
    explained: float
    """Share of the baseline's excess held-out mean square (above noise) this step removed."""
    delta_bic_train: float
    delta_chi2_heldout: float
    of_remaining: float = 0.0
    """Share of the excess that the effects ranked before it left, which this one removed."""
    established: bool = True
    """Admissible, on no search bound, needed again on resampled folds, material
    (:mod:`serpar.diagnosis.stability`); else only suspected."""
    reasons: tuple[str, ...] = ()
    """Why it is only suspected."""
    stability: float | None = None
    """Share of the resampled folds on which it earned its parameters again."""
    note: str = ""
    """A word on how to read the values, e.g. a negative payload as a nominal-model excess."""

    def words(self) -> str:
        shown = sorted(self.params, key=lambda p: -abs(p.value) / max(p.std, 1e-300))[:6]
        more = len(self.params) - len(shown)
        rest = (f" ({100 * self.of_remaining:.0f} % of what the effects above left)"
                if self.rank > 1 else "")
        held = (f"; needed on {100 * self.stability:.0f} % of resampled folds"
                if self.stability is not None else "")
        status = ("" if self.established
                  else f"suspected, not established ({'; '.join(self.reasons)}): ")
        note = f" ({self.note})" if self.note else ""
        return (f"{status}{self.summary}{note}: explains {100 * self.explained:.1f} % of the "
                f"held-out residual{rest}{held}; " + "; ".join(p.words() for p in shown)
                + (f"; and {more} more parameter(s)" if more > 0 else ""))

    def as_dict(self) -> dict[str, object]:
        return {"rank": self.rank, "effect": self.effect, "summary": self.summary,
                "explained_share": self.explained, "share_of_remaining": self.of_remaining,
                "delta_bic_train": self.delta_bic_train,
                "delta_chi2_heldout": self.delta_chi2_heldout,
                "established": self.established, "reasons": list(self.reasons),
                "resampled_frequency": self.stability, "note": self.note,
                "params": [p.as_dict() for p in self.params]}


@dataclass(frozen=True)
class Diagnosis:
    kind: str
    verdict: str
    findings: tuple[Finding, ...]
    candidates: tuple[CandidateScore, ...]
    locate_before: tuple[LocateRow, ...]
    locate_after: tuple[LocateRow, ...]
    baseline_params: tuple[ParamEstimate, ...]
    n_train_rows: int
    n_heldout_rows: int
    heldout_rms_before: float
    """Whitened RMS of the held-out residual of the baseline fit (1 = noise floor)."""
    heldout_rms_after: float
    heldout_p_after: float
    explained: float
    wall_s: float
    model: dict[str, object] = field(default_factory=dict)
    """The updated model: every fitted block's parameters by name (the model file)."""
    heldout_before: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    heldout_after: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    heldout_rows: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    residual: ResidualCheck | None = None
    """What the held-out residual after the fit of the established effects looks like."""
    empirical: EmpiricalTerm | None = None
    """What is left, characterised over the family's basis library (None: not tried: the
    residual passed the noise test, looked like noise, or the family has no library)."""
    physical: PhysicalResidual | None = None
    """The held-out residual in physical units per channel (None: the family cannot say)."""
    not_identifiable: tuple[str, ...] = ()
    """Candidates the recording cannot identify at all, each with why (an episode with one
    chamfer slide: the bore's friction)."""

    @property
    def established(self) -> tuple[Finding, ...]:
        return tuple(f for f in self.findings if f.established)

    @property
    def suspected(self) -> tuple[Finding, ...]:
        return tuple(f for f in self.findings if not f.established)

    @property
    def top_effect(self) -> str | None:
        """The first established finding (a suspected one is not a finding)."""
        return self.established[0].effect if self.established else None

    def evidence(self) -> dict[str, str]:
        """Why each established effect was kept, one line each (the model file's evidence)."""
        return {f.effect: (f"explains {100 * f.explained:.1f} % of the held-out residual"
                           + (f", needed on {100 * f.stability:.0f} % of resampled folds"
                              if f.stability is not None else "")
                           + f"; whole fit: held-out RMS {self.heldout_rms_before:.3g} -> "
                           f"{self.heldout_rms_after:.3g} x noise")
                for f in self.established}

    def model_file(self, source: str) -> dict[str, object]:
        """The model file's JSON (sim/model_file.py): the fitted model, its source, evidence."""
        return {"source": source, **self.model, "evidence": self.evidence()}

    @property
    def no_missing_physics(self) -> bool:
        return self.verdict == NO_MISSING_PHYSICS

    def as_dict(self) -> dict[str, object]:
        return {"kind": self.kind, "verdict": self.verdict, "top_effect": self.top_effect,
                "findings": [f.as_dict() for f in self.findings],
                "candidates": [c.as_dict() for c in self.candidates],
                "locate_before": [r.as_dict() for r in self.locate_before],
                "locate_after": [r.as_dict() for r in self.locate_after],
                "baseline_params": [p.as_dict() for p in self.baseline_params],
                "n_train_rows": self.n_train_rows, "n_heldout_rows": self.n_heldout_rows,
                "heldout_rms_whitened_before": self.heldout_rms_before,
                "heldout_rms_whitened_after": self.heldout_rms_after,
                "heldout_p_after": self.heldout_p_after,
                "explained_share": self.explained, "wall_s": self.wall_s,
                "established": [f.effect for f in self.established],
                "suspected": [f.effect for f in self.suspected],
                "residual_check": None if self.residual is None else self.residual.as_dict(),
                "empirical": None if self.empirical is None else self.empirical.as_dict(),
                "heldout_rms_physical": None if self.physical is None else self.physical.as_dict(),
                "not_identifiable": list(self.not_identifiable), "model": self.model}
