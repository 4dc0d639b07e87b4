"""The model refitted together with an empirical term: the family with the chosen basis
groups as one more block, so that the baseline and the established effects take back what
the missing physics had pushed into them (a ripple biases the tares; once it is modelled,
the tares move back, and no drift is needed to make up the difference)."""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from serpar.diagnosis.empirical import BasisGroup, Refit, design
from serpar.diagnosis.family import Effect, Family
from serpar.diagnosis.fit import Fit, earns, fit_model

Vec = NDArray[np.float64]
Rows = NDArray[np.int64]

EMPIRICAL = "empirical"


class WithTerm:
    """``family`` plus the columns of the ``chosen`` groups as the block ``"empirical"``."""

    def __init__(self, family: Family, groups: list[BasisGroup], chosen: list[int],
                 n_channels: int) -> None:
        self.inner, self.kind = family, family.kind
        self.baseline, self.n_samples = family.baseline, family.n_samples
        self._groups, self._chosen, self._channels = groups, list(chosen), n_channels
        names = tuple(f"{groups[g].channel}:{groups[g].label}[{i}]" for g in chosen
                      for i in range(groups[g].width))
        k = len(names)
        units = tuple(groups[g].unit for g in chosen for _ in range(groups[g].width))
        self.block = Effect(EMPIRICAL, "empirical term", names, units, np.zeros(k),
                            np.full(k, -np.inf), np.full(k, np.inf))
        self.effects = tuple(family.effects) + (self.block,)
        if callable(getattr(family, "jacobian", None)):
            self.jacobian = self._jacobian
        if callable(getattr(family, "baseline_columns", None)):
            self.baseline_columns = self._baseline_columns

    def _inner(self, params: Mapping[str, Vec]) -> dict[str, Vec]:
        return {n: v for n, v in params.items() if n != EMPIRICAL}

    def residual(self, params: Mapping[str, Vec], rows: Rows) -> Vec:
        r = self.inner.residual(self._inner(params), rows)
        if EMPIRICAL not in params:
            return r
        r = r - design(self._groups, self._chosen, rows, self._channels) @ params[EMPIRICAL]
        band = self._band(params[EMPIRICAL], rows)[0]
        # the inner residual is already outside its own band: a second dead zone adds to it
        return r if band is None else np.sign(r) * np.maximum(np.abs(r) - band, 0.0)

    def _band(self, coef: Vec, rows: Rows) -> tuple[Vec | None, Vec]:
        """(band, d band / d coef): the whitened stiction band the chosen friction groups give
        their channels (None where none is a friction): as wide as the level of the channel's
        friction as motion starts, where that opposes motion."""
        weight: dict[int, Vec] = {}
        level: dict[int, float] = {}
        onset: dict[int, Vec] = {}
        at = 0
        for g in self._chosen:
            group = self._groups[g]
            rest, column = group.rest, group.column
            if rest is not None and column is not None:
                weight.setdefault(column, np.asarray(rest.weight(rows), float))
                part = np.zeros(coef.size)
                part[at:at + group.width] = rest.onset
                onset[column] = onset.get(column, np.zeros(coef.size)) + part
                level[column] = level.get(column, 0.0) + float(part @ coef)
            at += group.width
        if not weight:
            return None, np.zeros((0, coef.size))
        band = np.zeros((len(rows), self._channels))
        slope = np.zeros((len(rows) * self._channels, coef.size))
        for column, w in weight.items():
            if level[column] > 0.0:
                band[:, column] = w * level[column]
                slope[column::self._channels] = w[:, None] * onset[column]
        return band.ravel(), slope

    def _before_band(self, params: Mapping[str, Vec], rows: Rows) -> Vec:
        """The residual with the term, before the term's own stiction band."""
        return self.inner.residual(self._inner(params), rows) - (
            design(self._groups, self._chosen, rows, self._channels) @ params[EMPIRICAL])

    def _jacobian(self, params: Mapping[str, Vec], rows: Rows, skip: Collection[str] = ()) -> Vec:
        """Columns in block order, the blocks in ``skip`` left out."""
        jacobian = self.inner.jacobian  # type: ignore[attr-defined]
        inner = (jacobian(self._inner(params), rows, skip) if skip  # a family's own may lack it
                 else jacobian(self._inner(params), rows))
        if EMPIRICAL not in params:
            return inner
        own = EMPIRICAL not in skip
        jac = (np.hstack([inner, -design(self._groups, self._chosen, rows, self._channels)])
               if own else inner)
        band, slope = self._band(params[EMPIRICAL], rows)
        if band is None:
            return jac
        r = self._before_band(params, rows)
        if own:
            jac[:, inner.shape[1]:] -= np.sign(r)[:, None] * slope
        jac[np.abs(r) <= band] = 0.0  # inside the band nothing moves the residual
        return jac
        r = self._before_band(params, rows)
        jac[:, inner.shape[1]:] -= np.sign(r)[:, None] * slope
        jac[np.abs(r) <= band] = 0.0  # inside the band nothing moves the residual
        return jac

    def _baseline_columns(self, params: Mapping[str, Vec], rows: Rows) -> sp.csr_matrix | Vec:
        """The inner family's (the term's columns do not depend on the baseline), zero where
        the term's stiction band holds the residual."""
        cols = self.inner.baseline_columns(self._inner(params), rows)  # type: ignore[attr-defined]
        if EMPIRICAL not in params:
            return cols
        band = self._band(params[EMPIRICAL], rows)[0]
        if band is None:
            return cols
        outside = (np.abs(self._before_band(params, rows)) > band).astype(float)
        return sp.csr_matrix(sp.diags(outside) @ cols) if sp.issparse(cols) else cols * outside[:, None]

    def split(self, rng: np.random.Generator) -> tuple[Rows, Rows]:
        return self.inner.split(rng)

    def locate(self, rows: Rows, whitened: Vec) -> list:
        return self.inner.locate(rows, whitened)


def model_refit(family: Family, kept: Fit, overrides: Mapping[str, Effect],
                groups: list[BasisGroup], n_channels: int) -> Callable[[Rows, Rows], Refit]:
    """``refit_on(train, held)`` for :func:`~serpar.diagnosis.empirical.characterise`: the
    kept model refitted on ``train``, alone or together with the chosen groups (on a
    resampled fold the groups must then earn over the model fitted to the same rows, not over
    one fitted to rows the fold holds out)."""

    def refit_on(train: Rows, held: Rows) -> Refit:
        alone = fit_model(family, kept.active, train, held, kept.params, overrides)

        def refit(chosen: list[int]) -> tuple[Vec, Vec, Vec]:
            if not chosen:
                return (family.residual(alone.params, train),
                        family.residual(alone.params, held), np.zeros(0))
            w = WithTerm(family, groups, chosen, n_channels)
            f = fit_model(w, kept.active + (EMPIRICAL,), train, held, kept.params, overrides)
            return w.residual(f.params, train), w.residual(f.params, held), f.params[EMPIRICAL]
        return refit
    return refit_on


def outweighed(family: Family, kept: Fit, overrides: Mapping[str, Effect],
               groups: list[BasisGroup], chosen: list[int], n_channels: int, train: Rows,
               held: Rows) -> list[str]:
    """Established effects of ``kept`` that no longer earn their parameters over the model
    with the empirical term in their place: what they explained, the empirical term explains
    (a joint-position error standing in for one leg's encoder scale, say), so naming them
    would name the wrong physics."""
    if not chosen:
        return []
    w = WithTerm(family, groups, chosen, n_channels)
    full = fit_model(w, kept.active + (EMPIRICAL,), train, held, kept.params, overrides)
    out = []
    for name in kept.active:
        rest = tuple(a for a in kept.active if a != name) + (EMPIRICAL,)
        without = fit_model(w, rest, train, held, kept.params, overrides)
        if not earns(without, full)[2]:
            out.append(name)
    return out
