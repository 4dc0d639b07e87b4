"""Redundant-parameter elimination (seed 003 §4.2) by a QR decomposition of the error Jacobian.

Seed 003 sorts the error parameters into three kinds from the columns of the identification
Jacobian, which this module finds numerically instead of by the paper's case analysis:

- non-functional: the column is zero, the parameter never changes what is measured
  (a tool rotation seen only through a point, the compliance of a joint gravity never loads);
- correlated: the column is a linear combination of columns kept before it, so only the
  combination can be identified and the parameter is fixed at nominal;
- independent: everything else, the base parameters that are identified.

Columns are scaled to unit norm (lengths, angles and compliances differ in units) and taken
in the order given, the order of preference: a column is kept when its distance from the span
of the columns before it (the ``|R_jj|`` of a QR factorisation in that order) exceeds
RANK_TOL.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from serpar.errors import IdentificationError

NULL_TOL = 1e-9
"""A column whose norm is below this fraction of the largest is non-functional."""
RANK_TOL = 1e-7
"""A unit column closer than this to the span of earlier columns is correlated with them
(exact redundancies sit at ~1e-13; a poorly but truly identifiable parameter far above)."""
WEAK_TOL = 0.05
"""An independent unit column closer than this to the span of all other independent ones is
weakly identifiable: its variance is inflated more than 1 / WEAK_TOL**2 = 400 times."""
COEF_TOL = 1e-6
"""Terms of a dependency smaller than this (scaled) are not named in the report."""


@dataclass(frozen=True)
class IdentifiabilityReport:
    """The classification of every parameter; correlated ones with their dependency."""

    names: tuple[str, ...]
    independent: tuple[int, ...]
    correlated: tuple[tuple[int, tuple[tuple[int, float], ...]], ...]
    """(parameter, ((independent parameter, coefficient), ...)): the parameter's Jacobian
    column equals that combination, so its error is absorbed by those parameters."""
    non_functional: tuple[int, ...]
    fixed: tuple[int, ...]
    """Parameters the model holds at nominal and never analysed."""
    condition: float
    """Condition number of the column-scaled Jacobian of the independent parameters."""
    weak: tuple[int, ...] = ()
    """Independent parameters that are nearly a combination of the others (see WEAK_TOL)."""

    @property
    def rank(self) -> int:
        return len(self.independent)

    def kind(self, name: str) -> str:
        i = self.names.index(name)
        if i in self.independent:
            return "weakly identifiable" if i in self.weak else "independent"
        if i in self.non_functional:
            return "non-functional"
        return "fixed" if i in self.fixed else "correlated"

    def relations(self, nuisance: str = "socket", max_terms: int | None = None) -> list[str]:
        """One line per correlated parameter, e.g. ``j1.d = +1 base.tz``; terms in nuisance
        parameters (names starting with ``nuisance``) are summarised as one; ``max_terms``:
        name only the first that many other terms and count the rest."""
        out = []
        for i, terms in self.correlated:
            named = [f"{c:+.4g} {self.names[k]}" for k, c in terms
                     if not self.names[k].startswith(nuisance)]
            n_named = len(named)
            if max_terms is not None and n_named > max_terms:
                named = named[:max_terms] + [f"... ({n_named - max_terms} more)"]
            if n_named < len(terms):
                named.append(f"{'+ ' if named else ''}the {nuisance} centres")
            out.append(f"{self.names[i]} = {' '.join(named) or '(noise level)'}")
        return out

    def as_dict(self) -> dict[str, object]:
        return {"independent": [self.names[i] for i in self.independent],
                "correlated": self.relations(),
                "non_functional": [self.names[i] for i in self.non_functional],
                "fixed": [self.names[i] for i in self.fixed],
                "weakly_identifiable": [self.names[i] for i in self.weak],
                "rank": self.rank, "condition": self.condition}


def identifiability(jac: NDArray[np.float64], names: tuple[str, ...],
                    fitted: NDArray[np.bool_] | None = None,
                    preference: NDArray[np.int64] | None = None) -> IdentifiabilityReport:
    """Classify the parameters (columns of ``jac``), keeping them in the order of
    ``preference`` (lower first, ties in column order; default column order)."""
    jac = np.asarray(jac, float)
    if jac.ndim != 2 or jac.shape[1] != len(names):
        raise IdentificationError(f"Jacobian of shape {jac.shape} does not match "
                                  f"{len(names)} parameter names")
    fitted = np.ones(len(names), bool) if fitted is None else np.asarray(fitted, bool)
    norms = np.linalg.norm(jac, axis=0)
    scale = norms[fitted].max() if fitted.any() else 0.0
    functional = fitted & (norms > NULL_TOL * scale) if scale > 0 else np.zeros_like(fitted)
    rank_of = np.zeros(len(names)) if preference is None else np.asarray(preference)
    cols = np.array([c for c in np.lexsort((np.arange(len(names)), rank_of)) if functional[c]],
                    int)
    unit = jac[:, cols] / norms[cols]
    independent = sorted(int(c) for c in cols[_kept_in_order(unit)])
    ind = np.array(independent, int)
    correlated: list[tuple[int, tuple[tuple[int, float], ...]]] = []
    dependent = np.array([c for c in sorted(cols) if c not in independent], int)
    if ind.size:
        basis = jac[:, ind] / norms[ind]
        coef = np.linalg.lstsq(basis, jac[:, dependent] / norms[dependent], rcond=None)[0]
        for c, col in zip(dependent, coef.T):
            correlated.append((int(c), tuple((int(k), float(a * norms[c] / norms[k]))
                                             for k, a in zip(ind, col) if abs(a) > COEF_TOL)))
        sv = np.linalg.svd(basis, compute_uv=False)
        condition = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
        # distance of each unit column from the span of all the others: 1 / sqrt(VIF)
        inflation = np.diag(np.linalg.pinv(basis.T @ basis))
        weak = tuple(int(k) for k, v in zip(ind, inflation) if v * WEAK_TOL**2 > 1.0)
    else:
        correlated = [(int(c), ()) for c in dependent]
        condition, weak = float("inf"), ()
    return IdentifiabilityReport(
        tuple(names), tuple(independent), tuple(correlated),
        tuple(int(i) for i in np.flatnonzero(fitted & ~functional)),
        tuple(int(i) for i in np.flatnonzero(~fitted)), condition, weak)


def _kept_in_order(unit: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Columns (unit norm) farther than RANK_TOL from the span of the kept columns before them:
    Gram-Schmidt with re-orthogonalisation, which (unlike an unpivoted Householder QR past a
    dependent column) measures the distance to exactly that span."""
    basis = np.zeros((unit.shape[0], 0))
    kept = np.zeros(unit.shape[1], bool)
    for j in range(unit.shape[1]):
        v = unit[:, j].copy()
        for _ in range(2):
            v -= basis @ (basis.T @ v)
        dist = float(np.linalg.norm(v))
        if dist > RANK_TOL:
            kept[j] = True
            basis = np.column_stack([basis, v / dist])
    return kept


def check_design(actual: IdentifiabilityReport, generic: IdentifiabilityReport,
                 n_poses: int, n_rows: int) -> None:
    """Raise if the campaign has fewer equations than identifiable parameters, or if its
    poses leave parameters unidentifiable that a generic pose set of the same layout
    identifies (``generic``: the same model on random joint angles)."""
    if n_rows < generic.rank:
        per_pose = max(1, n_rows // max(n_poses, 1))
        need = -(-generic.rank // per_pose)
        raise IdentificationError(
            f"{n_poses} poses give {n_rows} equations for {generic.rank} identifiable "
            f"parameters; need at least {need} poses (more for a useful fit)")
    if actual.rank < generic.rank:
        lost = [actual.names[i] for i in generic.independent if i not in actual.independent]
        shown = ", ".join(lost[:6]) + (f" and {len(lost) - 6} more" if len(lost) > 6 else "")
        raise IdentificationError(
            f"the pose set is rank deficient: it identifies {actual.rank} of the model's "
            f"{generic.rank} independent parameters ({shown} cannot be separated); add poses "
            "that move every joint over a wide range")
