"""Diagnosis against a prior model (``serpar diagnose REC --model M``): the effects of a previous
diagnosis's model file are part of the nominal prediction, fixed at their values.

:class:`PriorFamily` wraps a family. Every call of the residual gets the prior's blocks as
always-present parameters, so the baseline refit and every candidate see the nominal model
plus M. An effect that M holds stays a candidate, re-expressed as a *correction* (value = M's
+ correction, bounds shifted, start 0): it is kept only if the recording shows that M's values
are off by more than the noise allows. The written model is the combined one (M's effects,
updated by any correction, plus the new ones), so it can be the next run's plant model.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from serpar.diagnosis.family import Effect, Family, LocateRow
from serpar.diagnosis.select import SelectConfig
from serpar.errors import IdentificationError
from serpar.sim.model_file import DiagnosisModel

Vec = NDArray[np.float64]


PASSED_THROUGH = ("folds", "noise_ratio", "channels", "empirical_library", "in_units",
                  "residual_parts", "not_identifiable", "row_phases", "phase_checked")
"""Optional Family hooks a prior leaves as the inner family has them."""


def _fixed_values(model: DiagnosisModel, effect: Effect) -> tuple[Vec, Vec]:
    """The prior's values and std of ``effect``, in the family's parameter order. A parameter
    the prior lacks is at its nominal 0; one the family lacks must be 0 in the prior."""
    block = model.block(effect.name)
    prior = dict(zip(block.names, zip(block.values, block.std)))
    extra = [f"{n} = {v:.3g}" for n, (v, _) in prior.items() if n not in effect.param_names and v]
    if extra:
        raise IdentificationError(
            f"{model.path}: {effect.name} parameter(s) {', '.join(extra)} are not among what this "
            f"recording identifies ({', '.join(effect.param_names)}), so they cannot be held "
            "fixed in its model; diagnose against a model file without them")
    values = np.array([prior.get(n, (0.0, 0.0))[0] for n in effect.param_names])
    std = np.array([prior.get(n, (0.0, 0.0))[1] for n in effect.param_names])
    outside = [f"{n} = {v:.3g}" for n, v, lo, hi in
               zip(effect.param_names, values, effect.lower, effect.upper) if not lo <= v <= hi]
    if outside:
        raise IdentificationError(f"{model.path}: {effect.name} {', '.join(outside)} outside the "
                                  "range this family fits; not a model of this arm")
    return values, std


class PriorFamily:
    """``inner`` with the effects of ``model`` fixed in its nominal prediction."""

    def __init__(self, inner: Family, model: DiagnosisModel) -> None:
        by_name = {e.name: e for e in inner.effects}
        missing = [e for e in model.effects if e not in by_name]
        if missing:
            raise IdentificationError(
                f"{model.path} ({model.kind}) holds effect(s) {', '.join(missing)} that the "
                f"{inner.kind} family cannot take as fixed; its effects: "
                f"{', '.join(by_name) or 'none'}")
        self.inner, self.model = inner, model
        self.kind = f"{inner.kind}, against {model.path}"
        self.n_samples = inner.n_samples
        self.fixed: dict[str, Vec] = {}
        self.fixed_std: dict[str, Vec] = {}
        for name in model.effects:
            self.fixed[name], self.fixed_std[name] = _fixed_values(model, by_name[name])
        self.effects: tuple[Effect, ...] = tuple(
            self._correction(e) if e.name in self.fixed else e for e in inner.effects)
        if callable(getattr(inner, "jacobian", None)):
            self.jacobian = self._jacobian
        if callable(getattr(inner, "baseline_columns", None)):
            self.baseline_columns = self._baseline_columns
        # the inner family's optional hooks do not depend on the parameters: its own folds (an
        # episode deals its chamfer slides to them), noise estimate, channels and library
        for hook in PASSED_THROUGH:
            if hasattr(inner, hook):
                setattr(self, hook, getattr(inner, hook))

    @property
    def max_effects(self) -> int:
        return int(getattr(self.inner, "max_effects", SelectConfig.max_effects))

    @property
    def baseline(self) -> Effect | None:
        # the inner family's, read live: a family may settle its baseline in split()
        # (diagnosis/episode_family.py pins its drifting tare's knots to the training rows)
        return self.inner.baseline

    def _correction(self, e: Effect) -> Effect:
        f = self.fixed[e.name]
        return replace(e, summary=f"{e.summary}, correction to {self.model.path}",
                       x0=np.zeros_like(f), lower=e.lower - f, upper=e.upper - f)

    def _merged(self, params: Mapping[str, Vec]) -> dict[str, Vec]:
        """The blocks fitted now (corrections added to the prior), then the prior's others."""
        out = {k: v + self.fixed[k] if k in self.fixed else v for k, v in params.items()}
        out.update({k: v for k, v in self.fixed.items() if k not in params})
        return out

    # -- Family protocol -------------------------------------------------------------------
    def residual(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec:
        return self.inner.residual(self._merged(params), rows)

    def _jacobian(self, params: Mapping[str, Vec], rows: NDArray[np.int64],
                  skip: Collection[str] = ()) -> Vec:
        # columns in block order: the fitted blocks come first in the merged mapping, and a
        # correction's derivative is its full value's (value = prior + correction); the
        # prior's blocks not fitted now are left out, not computed and cut off
        held = {k for k in self.fixed if k not in params}
        jacobian = self.inner.jacobian  # type: ignore[attr-defined]
        if not (skip or held):  # a family's own Jacobian may not take skip
            return jacobian(self._merged(params), rows)
        return jacobian(self._merged(params), rows, {*skip, *held})

    def _baseline_columns(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                          ) -> sp.csr_matrix:
        return self.inner.baseline_columns(self._merged(params), rows)  # type: ignore[attr-defined]

    def split(self, rng: np.random.Generator) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        return self.inner.split(rng)

    def locate(self, rows: NDArray[np.int64], whitened: Vec) -> list[LocateRow]:
        return self.inner.locate(rows, whitened)

    # -- the updated model -----------------------------------------------------------------
    def combined_model(self, fitted: Mapping[str, object]) -> dict[str, object]:
        """The model file of prior + this diagnosis: a corrected effect's value is the prior's
        plus the correction (its std the correction's: the prior is a constant here); an
        uncorrected one keeps the prior's value and std."""
        params = dict(fitted["params"])  # type: ignore[call-overload]
        new = list(fitted["effects"])  # type: ignore[call-overload]
        for name, value in self.fixed.items():
            if name in params:
                block = dict(params[name])
                block["values"] = [float(v) for v in np.asarray(block["values"]) + value]
                params[name] = block
            else:
                params[name] = {"values": [float(v) for v in value],
                                "std": [float(s) for s in self.fixed_std[name]],
                                "names": list(next(e for e in self.effects
                                                   if e.name == name).param_names)}
        effects = list(self.model.effects) + [e for e in new if e not in self.fixed]
        return {"kind": self.inner.kind, "effects": effects, "params": params,
                "prior_model": self.model.path}
