"""Stage "outside the library": characterise a structured residual that no candidate explains,
as a sparse empirical term over a library of basis functions, and name it as a hypothesis.

A family offers ``empirical_library() -> list[BasisGroup]``: small groups of basis columns,
each tied to one residual channel (a joint's torque channel, a leg), one variable (a joint
angle, its velocity, time, a leg's stroke) and one shape (periodic in the variable, a step at
its reversal, a fall from standstill, a proportion, a drift). Each column is the change of the
whitened residual per unit coefficient, so a fit is weighted least squares in physical units.

Selection is forward and sparse, with the price every candidate effect pays
(:func:`serpar.diagnosis.fit.earns`): a group of k columns enters only when its chi-square drop
exceeds k ln(n) on the training rows *and* on the held-out rows. A selected group is kept
only when, refitted with the model and the others on each resampled fold, it is material
and acts the same way on ``MIN_FREQUENCY`` of them. A kept group's speed or time constant is
then refined (:func:`tune`). Whatever is kept is a labelled empirical term, never a named physical effect:
its words say what it looks like and why that is a hypothesis.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar

from serpar.diagnosis.empirical_term import (
    SHAPES,
    BasisGroup,
    EmpiricalTerm,
    Refit,
    RestBand,
    Term,
    Tuning,
    columns_at,
    design,
)
from serpar.diagnosis.empirical_tune import tune
from serpar.diagnosis.stability import MIN_FREQUENCY

Vec = NDArray[np.float64]
Rows = NDArray[np.int64]

MAX_TERMS = 4
"""Most groups one empirical term holds where the residual has fewer channels; where it has
more, one per channel (a friction form in every drive of an arm is a group per drive). More
than that is a model of its own, not a residual."""
SHORTLIST = 6
"""Groups that best fit what is left, each refitted with the model at each step; of those
that earn on both splits and are material, the one that removes most held-out residual
enters. The best fit on training rows alone may be a linear drift that the held-out rows
(later in time) refute, where a saturating one holds."""
MIN_OWN_SHARE = 0.05
"""A group's own contribution on the held-out rows must reach this share of the excess
held-out chi-square before it, in the channel it acts on (all channels for a group over the
whole residual), and its own price: with a many-parameter model refitted alongside, a group
of negligible size can otherwise "earn" by letting the model's parameters move. Per channel:
a drive whose friction leaves 6 x sigma is material beside another's 12 x sigma."""


def _excess(r: Vec, column: int | None, n_channels: int) -> float:
    """Excess chi-square of the held-out residual ``r`` (row-major) over unit noise, in one
    channel or (None) in all."""
    part = r if column is None else r.reshape(-1, n_channels)[:, column]
    return max(float(part @ part) - part.size, 0.0)


def _material(group: BasisGroup, own: Vec, before: Vec, n_channels: int) -> bool:
    """Whether a group's own held-out contribution ``own`` is material beside what was left in
    its channel (``before``: the held-out residual without it, row-major)."""
    size = float(own @ own)
    return (size >= MIN_OWN_SHARE * _excess(before, group.column, n_channels)
            and size > group.width * np.log(max(before.size, 2)))


def _earns_in_motion(group: BasisGroup, before: Vec, after: Vec, rows: Rows,
                     n_channels: int) -> bool:
    """A friction (a group with a stiction band) must earn its columns where its joint moves:
    at rest its band would otherwise "explain" noise (a wider band holds more of it) and a
    friction of any level would pay for itself on a joint that is often stuck."""
    if group.rest is None or group.column is None:
        return True
    moving = np.ones((len(rows), n_channels), bool)
    moving[:, group.column] = np.asarray(group.rest.weight(rows)) == 0.0
    m = moving.ravel()
    drop = float(before[m] @ before[m] - after[m] @ after[m])
    return drop > group.width * np.log(max(before.size, 2))


def _drop(group: BasisGroup, x: Vec, r: Vec, rows: Rows) -> float:
    """Chi-square drop of projecting the residual ``r`` (rows, channels) onto ``x``; for a
    friction with a stiction band, of the best level with its band (a residual left mostly
    where the joint is held at rest projects poorly onto the motion's sign alone)."""
    y = r[:, group.column] if group.column is not None else r.ravel()
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    fit = x @ coef
    linear = float(2 * y @ fit - fit @ fit)
    if group.rest is None or x.shape[1] != 1:
        return linear
    w = np.asarray(group.rest.weight(rows), float) * group.rest.onset[0]

    def left(c: float) -> float:
        z = y - x[:, 0] * c
        return float(np.sum(np.maximum(np.abs(z) - w * max(c, 0.0), 0.0) ** 2))
    reach = 4.0 * abs(float(coef[0])) + 1e-12
    best = minimize_scalar(left, bounds=(-reach, reach), method="bounded",
                           options={"xatol": 1e-3 * reach})
    return max(linear, float(y @ y) - best.fun)


def _screen(groups: list[BasisGroup], rows: Rows, r: Vec, cache: dict[tuple[int, int], Vec]
            ) -> list[tuple[float, int]]:
    """(score, group index): how much of what is left (``r``: rows x channels) each group
    explains. A channel-local group: its projection (groups on different channels are
    orthogonal). Groups over the whole residual that share a label (one leg each, say) can be
    strongly correlated, and a signal of two of them may project best onto a third: each is
    scored by what it adds to the others of its label and to what the model may hold of them
    (``beside``), fitted together."""
    out = []
    dense: dict[str, list[int]] = {}
    for i, g in enumerate(groups):
        if g.column is None:
            dense.setdefault(g.label, []).append(i)
        else:
            out.append((_drop(g, columns_at(g, rows, cache), r, rows), i))
    y = r.ravel()
    for members in dense.values():
        xs = [columns_at(groups[i], rows, cache) for i in members]
        besides = [np.asarray(b(rows), float).reshape(len(y), -1)
                   for b in (groups[i].beside for i in members) if b is not None]
        alone = _added(xs, [], y)
        # beside what the model may hold of them: where it holds it, what they add is that
        # part; where it does not, they add the whole, as alone
        scores = np.maximum(alone, _added(xs, besides, y)) if besides else alone
        out += [(float(score), i) for score, i in zip(scores, members)]
    return out


def _added(xs: list[Vec], besides: list[Vec], y: Vec) -> Vec:
    """Per group of columns ``xs``: the chi-square of ``y`` that the others and ``besides``,
    fitted together with it, cannot make up without it."""
    x = np.hstack(xs + besides)
    gram_inv = np.linalg.pinv(x.T @ x)
    coef = gram_inv @ (x.T @ y)
    edges = np.cumsum([0] + [b.shape[1] for b in xs])
    out = np.empty(len(xs))
    for m in range(len(xs)):
        sl = slice(edges[m], edges[m + 1])
        out[m] = float(coef[sl] @ np.linalg.pinv(gram_inv[sl, sl]) @ coef[sl])
    return out


def fixed_refit(groups: list[BasisGroup], r_train: Vec, r_held: Vec, train: Rows, held: Rows,
                n_channels: int) -> Refit:
    """The groups fitted to a fixed residual (the model's own parameters not refitted)."""
    cache: dict[tuple[int, int], Vec] = {}

    def refit(chosen: list[int]) -> tuple[Vec, Vec, Vec]:
        x_t = design(groups, chosen, train, n_channels, cache)
        coef = np.linalg.lstsq(x_t, r_train, rcond=None)[0] if chosen else np.zeros(0)
        return (r_train - x_t @ coef,
                r_held - design(groups, chosen, held, n_channels, cache) @ coef, coef)
    return refit


def select_terms(groups: list[BasisGroup], refit: Refit, train: Rows, held: Rows,
                 n_channels: int, max_terms: int | None = None) -> list[tuple[int, Vec, float]]:
    """Forward selection: the group that best fits what is left enters, refitted with the
    model, when it earns its columns on both splits. (group index, coefficients, held-out
    chi-square drop) in the order they entered; the coefficients of the last joint fit.
    ``max_terms``: default, :data:`MAX_TERMS` or one per channel where there are more."""
    if max_terms is None:
        max_terms = max(MAX_TERMS, n_channels)
    cache: dict[tuple[int, int], Vec] = {}
    res_t, res_h, _ = refit([])
    chosen: list[int] = []
    drops: list[float] = []
    coef = np.zeros(0)
    while len(chosen) < max_terms:
        r = res_t.reshape(len(train), n_channels)
        taken = {groups[c].key for c in chosen}
        scores = [(d, i) for d, i in _screen(groups, train, r, cache) if groups[i].key not in taken]
        if not scores:
            break
        best = None
        for _, i in sorted(scores, reverse=True)[:SHORTLIST]:
            k = columns_at(groups[i], train, cache).shape[1]
            new_t, new_h, new_coef = refit(chosen + [i])
            train_drop = float(res_t @ res_t - new_t @ new_t)
            held_drop = float(res_h @ res_h - new_h @ new_h)
            # its own share of the held-out prediction, not the model's refit, must be material
            own = design(groups, [i], held, n_channels, cache) @ new_coef[-k:]
            material = _material(groups[i], own, res_h, n_channels)
            if (train_drop > k * np.log(res_t.size) and held_drop > k * np.log(res_h.size)
                    and material and _earns_in_motion(groups[i], res_t, new_t, train, n_channels)
                    and _earns_in_motion(groups[i], res_h, new_h, held, n_channels)
                    and (best is None or held_drop > best[1])):
                best = i, held_drop, new_t, new_h, new_coef
        if best is None:
            break
        chosen.append(best[0])
        drops.append(best[1])
        res_t, res_h, coef = best[2], best[3], best[4]
    # a group that entered big and shrank once later ones came is no longer material: leave
    # it out and refit the rest
    held0 = refit([])[1] if chosen else np.zeros(0)
    while chosen:
        sizes = np.cumsum([0] + [columns_at(groups[c], train, cache).shape[1] for c in chosen])
        own = [design(groups, [g], held, n_channels, cache) @ coef[sizes[i]:sizes[i + 1]]
               for i, g in enumerate(chosen)]
        small = [i for i, o in enumerate(own)
                 if not _material(groups[chosen[i]], o, held0, n_channels)]
        if not small:
            break
        del chosen[small[0]], drops[small[0]]
        res_t, res_h, coef = refit(chosen)
    sizes = np.cumsum([0] + [columns_at(groups[c], train, cache).shape[1] for c in chosen])
    return [(g, coef[sizes[i]:sizes[i + 1]], drops[i]) for i, g in enumerate(chosen)]


def characterise(groups: list[BasisGroup], refit_on: Callable[[Rows, Rows], Refit],
                 train: Rows, held: Rows, splits: list[tuple[Rows, Rows]], n_channels: int,
                 every: Rows) -> EmpiricalTerm:
    """The empirical term on the main split (``refit_on(train, held)``: how the model is
    refitted with chosen groups on a split), each group kept only if it holds up on the
    folds (:func:`_held_on_folds`)."""
    main_refit = refit_on(train, held)
    _, r_h, _ = main_refit([])
    rms0 = float(np.sqrt(np.mean(r_h**2))) if r_h.size else 0.0
    main = select_terms(groups, main_refit, train, held, n_channels)
    if not main:
        return EmpiricalTerm((), rms0, rms0)
    counts = _held_on_folds(groups, [g for g, _, _ in main], [c for _, c, _ in main], refit_on,
                            held, splits, n_channels)
    n = max(len(splits), 1)
    keep = [m for m in main if not splits or counts[m[0]] / n >= MIN_FREQUENCY]
    kept_idx = {g for g, _, _ in keep}
    rejected = tuple(f"{groups[g].channel} {groups[g].shape} in {groups[g].variable} "
                     f"(material on {counts[g]} of {n} folds)"
                     for g, _, _ in main if g not in kept_idx)
    if not keep:
        return EmpiricalTerm((), rms0, rms0, rejected)
    idx = tune(groups, main_refit, [g for g, _, _ in keep], train, held, n_channels)
    _, after, coef = main_refit(idx)
    sizes = np.cumsum([0] + [groups[g].width for g in idx])
    terms = tuple(Term(groups[g], coef[sizes[i]:sizes[i + 1]], d,
                       counts[m] / n, _size(groups[g], coef[sizes[i]:sizes[i + 1]], every))
                  for i, (g, (m, _, d)) in enumerate(zip(idx, keep)))
    return EmpiricalTerm(terms, rms0, float(np.sqrt(np.mean(after**2))), rejected)


def _held_on_folds(groups: list[BasisGroup], chosen: list[int], coef: list[Vec],
                   refit_on: Callable[[Rows, Rows], Refit], held: Rows,
                   splits: list[tuple[Rows, Rows]], n_channels: int) -> dict[int, int]:
    """On how many folds each chosen group, refitted there with the model and the others,
    is material on the fold's held-out rows and acts the same way as on the main split (its
    contribution on the main held-out rows correlates positively). Where two shapes fit a
    channel almost alike (a smooth step or a Stribeck fall of the same drive), which one a
    forward selection picks can change from fold to fold; whether the chosen one holds up
    does not."""
    counts = {g: 0 for g in chosen}
    main_own = [design(groups, [g], held, n_channels) @ c for g, c in zip(chosen, coef)]
    edges = np.cumsum([0] + [groups[g].width for g in chosen])
    for f_train, f_held in splits:
        _, after, f_coef = refit_on(f_train, f_held)(chosen)
        if f_coef.size != edges[-1]:
            continue  # the fold's refit failed: it counts for none
        for i, g in enumerate(chosen):
            c = f_coef[edges[i]:edges[i + 1]]
            own = design(groups, [g], f_held, n_channels) @ c
            same_way = float((design(groups, [g], held, n_channels) @ c) @ main_own[i]) > 0.0
            if same_way and _material(groups[g], own, after + own, n_channels):
                counts[g] += 1
    return counts


def _size(group: BasisGroup, coef: Vec, every: Rows) -> float:
    """Range (a drift) or RMS (any other shape) over all rows of the group's contribution,
    in the channel's physical unit."""
    x = np.asarray(group.physical(every), float) @ coef
    return float(np.ptp(x)) if group.shape == "drift" else float(np.sqrt(np.mean(x**2)))


__all__ = ["SHAPES", "BasisGroup", "EmpiricalTerm", "Refit", "RestBand", "Term", "Tuning",
           "characterise", "design", "fixed_refit", "select_terms", "tune"]
