"""Stage "fit": one model (the baseline plus a set of active effects) by bounded least
squares on the training rows, scored on the held-out rows.

Price of a parameter (BIC's k ln n): n is the number of residual entries the parameter's block
moves. A family whose effects touch different parts of the data says so with the optional hook
``entries_of(effect, rows) -> int | None`` (None: every entry). An episode's journal/bore
friction moves its few chamfer-slide entries only, and its evidence grows with their number,
not with the arm's 10^5 entries beside them: priced at ln(10^5) it could never be earned by two
slides, whatever the friction (the effective sample size of a parameter, as for a group-level
parameter of a hierarchical model).

Uncertainty: the covariance of the whitened problem, (J^T J)^-1 at the optimum, scaled by the
reduced chi-square when that exceeds one (Birge ratio): a model that does not reach the
noise floor must not claim the noise-limited precision.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import OptimizeResult, least_squares

from serpar.diagnosis.family import Effect, Family
from serpar.diagnosis.separable import profile, projected
from serpar.errors import IdentificationError

BASELINE = "baseline"
"""Key of the baseline's parameters in a parameter mapping when the family's baseline has no
name of its own (the family's ``baseline.name`` is used otherwise)."""


@dataclass(frozen=True)
class Fit:
    """One fitted model: parameters per block, their 1-sigma uncertainty, the scores."""

    active: tuple[str, ...]
    """Effect names, baseline excluded, in the order they were added."""
    params: Mapping[str, NDArray[np.float64]]
    std: Mapping[str, NDArray[np.float64]]
    train_chi2: float
    n_train: int
    """Number of training residuals (not rows)."""
    heldout_chi2: float
    n_heldout: int
    n_params: int
    nfev: int
    price_train: float
    """Sum over the free parameters of ln(entries its block moves) on the training rows."""
    price_heldout: float
    """The same on the held-out rows."""

    @property
    def bic(self) -> float:
        """Known-noise BIC on the training residuals: chi^2 + sum of k ln n over the blocks."""
        return self.train_chi2 + self.price_train

    @property
    def train_rms(self) -> float:
        return float(np.sqrt(self.train_chi2 / max(self.n_train, 1)))

    @property
    def heldout_rms(self) -> float:
        return float(np.sqrt(self.heldout_chi2 / max(self.n_heldout, 1)))


def earns(current: Fit, new: Fit) -> tuple[float, float, bool]:
    """``new`` has the effects of ``current`` and more. (training BIC change, held-out chi^2 drop, whether the extra parameters are earned)."""
    k = new.n_params - current.n_params
    d_bic = new.bic - current.bic
    d_held = current.heldout_chi2 - new.heldout_chi2
    ok = k > 0 and d_bic < 0 and d_held > new.price_heldout - current.price_heldout
    return d_bic, d_held, ok


def price(family: Family, blocks: tuple[Effect, ...], rows: NDArray[np.int64],
          n_entries: int) -> float:
    """Sum over the blocks' free parameters of ln(the residual entries the block moves)."""
    hook = getattr(family, "entries_of", None)
    total = 0.0
    for b in blocks:
        n = hook(b.name, rows) if callable(hook) else None
        total += (b.n_params - len(b.fixed)) * float(np.log(max(n_entries if n is None else n, 2)))
    return total


def blocks_of(family: Family, active: tuple[str, ...],
              overrides: Mapping[str, Effect] | None = None) -> tuple[Effect, ...]:
    """The baseline (if any) followed by the named effects of the family (``overrides``: the
    same effects with some parameters fixed, by name)."""
    by_name = {e.name: e for e in family.effects} | dict(overrides or {})
    unknown = [a for a in active if a not in by_name]
    if unknown:
        raise IdentificationError(f"unknown effect(s) {', '.join(unknown)}; this recording's "
                                  f"candidates: {', '.join(by_name) or '(none)'}")
    base = (family.baseline,) if family.baseline is not None else ()
    return base + tuple(by_name[a] for a in active)


def unpack(blocks: tuple[Effect, ...], x: NDArray[np.float64]) -> dict[str, NDArray[np.float64]]:
    out, k = {}, 0
    for b in blocks:
        out[b.name] = np.asarray(x[k:k + b.n_params], float)
        k += b.n_params
    return out


TOLERANCES = {"ftol": 1e-10, "xtol": 1e-10, "gtol": 1e-10}
"""scipy's stopping rules, tight: a fit started on a bound with a large residual (a
frictionless model against a real arm) takes a first step too small for any looser ``ftol``."""
CRAWL_ITERATIONS = 10
CRAWL_SHARE = 1e-7
"""A fit whose last :data:`CRAWL_ITERATIONS` steps together lowered its chi^2 by less than this
share of it is done. Every decision the diagnosis takes is on chi^2 differences of order one
(k ln n per parameter, held-out drops); a misspecified fit (chi^2 in the millions) crawls along
its valley for thousands of evaluations under the tolerances above and moves its chi^2 by a
few units (a few 1e-6 of itself) doing so, while a fit near the noise stops on them first."""
CRAWL_EXCESS_SHARE = 1e-6
"""A fit is also done when its last :data:`CRAWL_ITERATIONS` steps lowered chi^2 by less than
this share of its excess over the noise (chi^2 minus its residual entries). A candidate that
cannot be what the data show (a friction form fitted while a hand's mass is missing, chi^2 at
400x the noise) otherwise descends by tens of units per ten steps for thousands of steps, a
few 1e-4 of its chi^2 in all, where what decides on it (its held-out chi^2 against the other
candidates', k ln n per parameter) is a thousand times coarser; near the noise the excess is
small and the rule above stops first."""


def _crawl_stop() -> Callable[[OptimizeResult], None]:
    """A least_squares callback that ends the fit when it crawls (:data:`CRAWL_SHARE`)."""
    costs: list[float] = []

    def callback(intermediate_result: OptimizeResult) -> None:  # scipy passes it by this name
        costs.append(float(intermediate_result.cost))  # chi^2 / 2
        excess = costs[-1] - 0.5 * np.size(intermediate_result.fun)
        if (len(costs) > CRAWL_ITERATIONS
                and costs[-1 - CRAWL_ITERATIONS] - costs[-1]
                < max(CRAWL_SHARE * costs[-1], CRAWL_EXCESS_SHARE * excess)):
            raise StopIteration

    return callback


START_INSIDE = 0.01
"""In a family that sets ``start_inside`` (an arm's dynamics against its own file), a new
effect's parameter whose x0 sits on a bound (no friction, no delay) starts this share of its
range inside: scipy's trust region starts as wide as the (scaled) start, and a start on zero
left a fit with a large residual (a CAD model against a real arm) stopped by ``ftol`` after
one tiny step. Other families keep their starts (a backlash fit started inside its clearance
bound converges to another minimum)."""


def _inside(effect: Effect) -> NDArray[np.float64]:
    x0, lo, hi = effect.x0, effect.lower, effect.upper
    with np.errstate(invalid="ignore"):  # an unbounded side is never the start's
        step = START_INSIDE * np.where(np.isfinite(hi - lo), hi - lo, 0.0)
    return np.where(x0 <= lo, lo + step, np.where(x0 >= hi, hi - step, x0))


def fit_model(family: Family, active: tuple[str, ...], train: NDArray[np.int64],
              heldout: NDArray[np.int64],
              start: Mapping[str, NDArray[np.float64]] | None = None,
              overrides: Mapping[str, Effect] | None = None) -> Fit:
    """Fit the baseline and the ``active`` effects on ``train``; score on ``heldout``.
    ``start``: parameters of a previous fit to begin from (blocks it lacks start at x0);
    ``overrides``: effects with parameters fixed (:meth:`Effect.fix`), by name."""
    blocks = blocks_of(family, active, overrides)
    start = start or {}
    inside = getattr(family, "start_inside", False)
    x0 = np.concatenate([np.clip(start[b.name], b.lower, b.upper) if b.name in start
                         else _inside(b) if inside else np.clip(b.x0, b.lower, b.upper)
                         for b in blocks] or [np.zeros(0)])
    lo = np.concatenate([b.lower for b in blocks] or [np.zeros(0)])
    hi = np.concatenate([b.upper for b in blocks] or [np.zeros(0)])
    # parameters held at zero (Effect.fix) are left out of the search, not boxed in
    free = _free_mask(blocks)
    x0[~free] = 0.0

    def full(xf: NDArray[np.float64]) -> NDArray[np.float64]:
        x = np.zeros(free.size)
        x[free] = xf
        return x

    def fun(xf: NDArray[np.float64]) -> NDArray[np.float64]:
        return family.residual(unpack(blocks, full(xf)), train)

    exact = getattr(family, "jacobian", None)
    if (callable(getattr(family, "baseline_columns", None)) and callable(exact)
            and family.baseline is not None and blocks[0] is family.baseline
            and not blocks[0].fixed):
        return _fit_separable(family, active, blocks, x0, free, lo, hi, train, heldout)
    if not free.any():
        r = fun(x0[free])
        return _score(family, active, blocks, x0, r, np.zeros((r.size, x0.size)), train, heldout,
                      1)
    # a family may offer its exact Jacobian (columns in block order); else 2-point differences
    jac = ("2-point" if not callable(exact)
           else (lambda xf: exact(unpack(blocks, full(xf)), train)[:, free]))
    n_free = int(free.sum())
    sol = least_squares(fun, x0[free], jac=jac, bounds=(lo[free], hi[free]), method="trf",
                        x_scale="jac", callback=_crawl_stop(), **TOLERANCES,
                        max_nfev=200 * (n_free + 1))
    if not np.all(np.isfinite(sol.fun)):
        raise IdentificationError(f"the fit of {'+'.join(active) or 'the baseline'} produced "
                                  "non-finite residuals")
    jac_full = np.zeros((sol.fun.size, free.size))
    jac_full[:, free] = sol.jac
    return _score(family, active, blocks, full(sol.x), sol.fun, jac_full, train, heldout,
                  int(sol.nfev))


def _fit_separable(family: Family, active: tuple[str, ...], blocks: tuple[Effect, ...],
                   x0: NDArray[np.float64], free: NDArray[np.bool_], lo: NDArray[np.float64],
                   hi: NDArray[np.float64], train: NDArray[np.int64],
                   heldout: NDArray[np.int64]) -> Fit:
    """:func:`fit_model` by variable projection (diagnosis/separable.py): the effects fitted on
    the residual with the baseline solved out at every evaluation."""
    base = blocks[0]
    nb = base.n_params
    outer = free.copy()
    outer[:nb] = False
    last: dict[str, object] = {"t": x0[:nb].copy()}

    def full(xo: NDArray[np.float64]) -> NDArray[np.float64]:
        x = np.zeros(free.size)
        x[:nb] = last["t"]
        x[outer] = xo
        return x

    def solve(xo: NDArray[np.float64]) -> NDArray[np.float64]:
        key = xo.tobytes()
        if last.get("key") != key:
            t, r = profile(family, unpack(blocks, full(xo)), base.name, base.lower, base.upper,
                           train)  # type: ignore[arg-type]
            last.update(key=key, t=t, r=r)
        return last["r"]  # type: ignore[return-value]

    def jac(xo: NDArray[np.float64]) -> NDArray[np.float64]:
        solve(xo)
        params = unpack(blocks, full(xo))
        # the effects' columns alone: the baseline's come sparse from baseline_columns
        j = family.jacobian(params, train, skip=(base.name,))[:, outer[nb:]]  # type: ignore[attr-defined]
        return projected(j, 0, family.baseline_columns(params, train))  # type: ignore[attr-defined]

    nfev = 1
    if outer.any():
        sol = least_squares(solve, x0[outer], jac=jac, bounds=(lo[outer], hi[outer]),
                            method="trf", x_scale="jac", callback=_crawl_stop(),
                            **TOLERANCES,
                            max_nfev=200 * (int(outer.sum()) + 1))
        xo, nfev = sol.x, int(sol.nfev)
    else:
        xo = x0[outer]
    r = solve(xo)
    if not np.all(np.isfinite(r)):
        raise IdentificationError(f"the fit of {'+'.join(active) or 'the baseline'} produced "
                                  "non-finite residuals")
    x = full(xo)
    jac_full = np.zeros((r.size, free.size))
    jac_full[:, free] = family.jacobian(unpack(blocks, x), train)[:, free]  # type: ignore[attr-defined]
    return _score(family, active, blocks, x, r, jac_full, train, heldout, nfev)


def _free_mask(blocks: tuple[Effect, ...]) -> NDArray[np.bool_]:
    return np.concatenate([np.isin(np.arange(b.n_params), b.fixed, invert=True) for b in blocks]
                          or [np.zeros(0, bool)])


def _score(family: Family, active: tuple[str, ...], blocks: tuple[Effect, ...],
           x: NDArray[np.float64], r: NDArray[np.float64], jac: NDArray[np.float64],
           train_rows: NDArray[np.int64], heldout: NDArray[np.int64], nfev: int) -> Fit:
    params = unpack(blocks, x)
    chi2 = float(r @ r)
    k = x.size - sum(len(b.fixed) for b in blocks)
    jac = np.asarray(jac, float)
    free = _free_mask(blocks)
    cov = np.zeros((x.size, x.size))
    if k:
        cov[np.ix_(free, free)] = np.linalg.pinv(jac[:, free].T @ jac[:, free])
    dof = max(r.size - k, 1)
    cov = cov * max(1.0, chi2 / dof)
    std = unpack(blocks, np.sqrt(np.clip(np.diag(cov), 0.0, None)))
    held = family.residual(params, heldout) if heldout.size else np.zeros(0)
    return Fit(active, params, std, chi2, int(r.size), float(held @ held), int(held.size), k,
               nfev, price(family, blocks, train_rows, int(r.size)),
               price(family, blocks, heldout, int(held.size)))
