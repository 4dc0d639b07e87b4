"""An assembly episode (``serpar run --record``) as a diagnosis family.

An episode recording holds the arm's own signals (q, tau_J, tau_J_d at 1 kHz) through every
phase of every hole cycle. In free motion the arm's torques are the arm's dynamics and
nothing else, so the arm-dynamics family (diagnosis/arm_dynamics_family.py) can tell which
of its physics the nominal model leaves out: the joint friction the controllers do not model,
a payload, a sensor gain, a delay. In the contact phases the journal, the tray, the pads and
the plate push on the hand, and those forces are not in any arm model: the controller's own
wrench estimate is the nominal model's inverse dynamics read backwards, so it cannot stand in
for them. This family therefore compares only the windows that lie wholly inside a
free-motion phase (:data:`FREE_PHASES`); every other sample is excluded *and reported*, per
phase, in the family's kind (the "where" table still shows every phase it kept).

The insert phases add one row per chamfer slide (diagnosis/insertion_friction.py): where an
off-centre journal slides down the 45 deg chamfer, the lateral/axial ratio of the wrench
estimate is (1 - mu)/(1 + mu), so journal/bore friction (``contact_friction``) is a candidate
when an episode has at least :data:`MIN_SLIDES` of them.

Training and held-out rows: alternate 2-s blocks of the free-motion windows (the arm-dynamics
family's split), so held-out rows are motions of other moments of the episode; alternate
insertions for the chamfer rows.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from serpar.diagnosis.arm_dynamics_family import ArmDynamicsConfig, ArmDynamicsFamily
from serpar.diagnosis.arm_dynamics_family import family_from_recording as dynamics_family
from serpar.diagnosis.arm_dynamics_jacobian import forward_step
from serpar.diagnosis.family import Effect, LocateRow
from serpar.diagnosis.insertion_friction import EFFECT as FRICTION
from serpar.diagnosis.insertion_friction import ChamferSlides, chamfer_slides
from serpar.diagnosis.locate import locate_rows
from serpar.diagnosis.residual import consecutive_noise_ratio
from serpar.diagnosis.stability import default_folds
from serpar.diagnosis.units import UnitView
from serpar.errors import IdentificationError
from serpar.sim.recording import Recording

Vec = NDArray[np.float64]

KIND = "episode"
EPISODE_PHASES = ("start", "register", "locate", "grasp", "inspect", "align", "insert", "release")
"""The phases ``serpar run --record`` writes (tasks/episode_recorder.py)."""
FREE_PHASES = ("start", "register", "locate", "inspect", "align")
"""Phases in which nothing but the held part touches the hand: settling at home, the arm
clearing the cameras, the transit to the inspect pair, the inspection and the carry to the
station above the plate. ``grasp`` (pads on a part in the tray), ``insert`` (journal in its
bore) and ``release`` (pads opening on a seated part) have contact forces on the hand."""
TARE_KNOT_S = 2.0
"""Knot spacing of the torque sensors' drifting tare: an episode runs for minutes and the
sensor zeros walk (the cell's sensor model: 0.002 N m/sqrt(s), i.e. ~0.006 N m in 10 s, about
twice a wrist joint's 1 ms-window noise); between knots 2 s apart the walk's bridge leaves
~0.001 N m. One knot per split block, so every knot is pinned by a training block."""
MAX_EFFECTS = 6
"""More than the engine's default 3: an episode holds the arm's dynamics (friction and its
Stribeck fall, the held part's mass, the cell's sensor timing and latency) and its insertions'
contact friction at once; the resampling rules decide which of them are established."""
MIN_SLIDES = 2
"""Chamfer slides an episode needs for the contact-friction candidate: one to fit, one to
hold out."""
PHASE_CHECKED = ("link_inertia", "link_inertial")
"""Effects established only where two free-motion phases show them alike
(diagnosis/phase_consistency.py): a link's mass loads every move with one number."""
MIN_ROWS = 40
"""Fewest free-motion windows an episode must give (about 2 s at the default window)."""


def is_episode(rec: Recording) -> bool:
    """Whether the recording is an assembly episode: its phases are the episode's."""
    names = {p.name for p in rec.meta.phases}
    return bool(names) and names <= set(EPISODE_PHASES) and "insert" in names


class EpisodeFamily:
    """The free-motion windows of an episode, diagnosed as arm dynamics, and its insertions'
    chamfer slides (diagnosis/insertion_friction.py), one row each after the windows."""

    def __init__(self, inner: ArmDynamicsFamily, keep: NDArray[np.int64],
                 excluded: Mapping[str, int], slides: ChamferSlides | None = None,
                 phases: NDArray[np.str_] | None = None) -> None:
        if len(keep) < MIN_ROWS:
            raise IdentificationError(
                f"the episode has {len(keep)} comparison windows in free motion "
                f"({', '.join(FREE_PHASES)}); at least {MIN_ROWS} are needed")
        self.inner, self.keep = inner, np.asarray(keep, np.int64)
        self.excluded = dict(excluded)
        self.slides = slides if slides is not None and slides.n >= MIN_SLIDES else None
        found = slides.n if slides is not None else 0
        self.not_identifiable: dict[str, str] = {} if self.slides else {
            FRICTION.name: f"{found} chamfer slide{'s' * (found != 1)} in these insertions, "
                           f"{MIN_SLIDES} needed (one to fit, one to hold out); the bore's "
                           "friction is not read from the other phases"}
        """Candidates these data cannot identify, with why (the verdict names them)."""
        self.baseline: Effect | None = inner.baseline
        self.effects: tuple[Effect, ...] = inner.effects + ((FRICTION,) if self.slides else ())
        self.max_effects = MAX_EFFECTS
        self.n_arm = len(self.keep)
        self.n_samples = self.n_arm + (self.slides.n if self.slides else 0)
        arm_phases = np.full(self.n_arm, "") if phases is None else np.asarray(phases, str)
        self.row_phases = np.concatenate([arm_phases, np.full(self.n_samples - self.n_arm, "")])
        """Each row's free-motion phase ("" for a chamfer slide): diagnosis/phase_consistency.py."""
        self.phase_checked = PHASE_CHECKED
        dropped = ", ".join(f"{n} in {p}" for p, n in self.excluded.items() if n)
        skipped = "; ".join(f"{n} {why}" for why, n in (slides.not_used if slides else {}).items())
        self.kind = (f"{KIND} (arm dynamics over {self.n_arm} free-motion windows; contact "
                     f"windows excluded: {dropped or 'none'}; {found} chamfer slide(s)"
                     + (f", insertions not used: {skipped}" if skipped else "")
                     + ("" if self.slides else f", fewer than {MIN_SLIDES}: contact friction "
                        "not a candidate") + ")")

    def _parts(self, rows: NDArray[np.int64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        rows = np.asarray(rows, np.int64)
        return rows[rows < self.n_arm], rows[rows >= self.n_arm] - self.n_arm

    def entries_of(self, effect: str, rows: NDArray[np.int64]) -> int | None:
        """The residual entries of ``rows`` the contact friction moves: the chamfer slides' (the
        price of its parameter, diagnosis/fit.py); every other effect: all (None)."""
        return self._parts(rows)[1].size if effect == FRICTION.name else None

    def residual(self, params: Mapping[str, Vec], rows: NDArray[np.int64]) -> Vec:
        """The arm rows' residuals (one per arm channel each) first, then one per chamfer slide."""
        arm, slide = self._parts(rows)
        out = self.inner.residual({k: v for k, v in params.items() if k != FRICTION.name},
                                  self.keep[arm])
        if self.slides is None or slide.size == 0:
            return out
        return np.concatenate([out, self.slides.residual(params.get(FRICTION.name), slide)])

    def jacobian(self, params: Mapping[str, Vec], rows: NDArray[np.int64],
                 skip: Collection[str] = ()) -> Vec:
        """The arm rows' Jacobian (the inner family's), then the chamfer slides', which only
        the contact friction moves (by differences, as the fit's own would take them); the
        blocks in ``skip`` left out."""
        arm, slide = self._parts(rows)
        inner = {k: v for k, v in params.items() if k != FRICTION.name}
        j_arm = self.inner.jacobian(inner, self.keep[arm], skip)
        sizes = {k: np.asarray(v).size for k, v in params.items() if k not in skip}
        n_slide = slide.size if self.slides is not None else 0
        out = np.zeros((j_arm.shape[0] + n_slide, sum(sizes.values())))
        col, inner_col = 0, 0
        for name, size in sizes.items():
            if name == FRICTION.name:
                if n_slide:
                    out[j_arm.shape[0]:, col] = self._slide_column(params[name], slide)
            else:
                out[:j_arm.shape[0], col:col + size] = j_arm[:, inner_col:inner_col + size]
                inner_col += size
            col += size
        return out

    def baseline_columns(self, params: Mapping[str, Vec], rows: NDArray[np.int64]
                         ) -> sp.csr_matrix:
        """The arm rows' tare columns; the chamfer slides do not depend on the tare."""
        arm, slide = self._parts(rows)
        inner = {k: v for k, v in params.items() if k != FRICTION.name}
        b = self.inner.baseline_columns(inner, self.keep[arm])
        n_slide = slide.size if self.slides is not None else 0
        return sp.vstack([b, sp.csr_matrix((n_slide, b.shape[1]))], format="csr")

    def _slide_column(self, d_mu: Vec, slide: NDArray[np.int64]) -> Vec:
        assert self.slides is not None
        x = np.asarray(d_mu, float)
        step = forward_step(float(x[0]))
        return (self.slides.residual(x + step, slide) - self.slides.residual(x, slide)) / step

    def folds(self, k: int) -> list[tuple[NDArray[np.int64], NDArray[np.int64]]]:
        """The engine's folds over the free-motion rows, with the chamfer slides dealt to the
        folds one by one (each fold must hold some out to judge contact friction)."""
        arm = default_folds(self.n_arm, k)
        if self.slides is None:
            return arm
        slides = self.n_arm + np.arange(self.slides.n)
        out = []
        for f, (train, held) in enumerate(arm):
            mine = slides[np.arange(self.slides.n) % len(arm) == f]
            out.append((np.r_[train, np.setdiff1d(slides, mine)], np.r_[held, mine]))
        return out

    def in_units(self, rows: NDArray[np.int64]) -> UnitView:
        """The arm rows' torque channels (N m), then one entry per chamfer slide: lateral minus
        the nominal friction ratio times axial force [N] (its measured value: the lateral)."""
        arm, slide = self._parts(rows)
        v = self.inner.in_units(self.keep[arm])
        if self.slides is None or slide.size == 0:
            return v
        k = len(v.channels)
        return UnitView(v.channels + ("chamfer slide lateral - g axial",), v.units + ("N",),
                        np.r_[v.channel, np.full(slide.size, k)],
                        np.r_[v.scale, self.slides.sigma(slide)],
                        np.r_[v.axis, self.slides.time[slide]], v.axis_label,
                        None if v.measured is None
                        else np.r_[v.measured, self.slides.lateral[slide]])

    def _split_whitened(self, rows: NDArray[np.int64], whitened: Vec
                        ) -> tuple[NDArray[np.int64], Vec, Vec]:
        """The arm rows (indices into ``keep``), their residual entries (one per arm channel each,
        first: 14 with a commanded torque, 7 without) and the chamfer slides' entries (one each,
        after them)."""
        arm, _ = self._parts(rows)
        w = np.asarray(whitened, float)
        k = len(self.inner.channels) * arm.size
        return arm, w[:k], w[k:]

    def noise_ratio(self, rows: NDArray[np.int64], whitened: Vec) -> tuple[float, str] | None:
        """The arm channels' noise over the stated sigma, from sample-to-sample differences."""
        arm, w_arm, _ = self._split_whitened(rows, whitened)
        r = consecutive_noise_ratio(self.keep[arm], w_arm, len(self.inner.channels))
        return None if r is None else (r, "sample-to-sample differences of the arm channels")

    def residual_parts(self, rows: NDArray[np.int64], whitened: Vec) -> dict[str, Vec]:
        """The arm channels' and the chamfer slides' residual entries: independent parts, each
        tested against noise on its own (three slides beside 10^5 arm entries move no total)."""
        _, w_arm, w_slides = self._split_whitened(rows, whitened)
        return {"arm": w_arm, "chamfer slides": w_slides}

    def split(self, rng: np.random.Generator) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        t = self.inner.terms.time[self.keep]
        # blocks counted from the recording's first row, as the tare's knots are
        block = np.floor((t - self.inner.terms.time[0]) / self.inner.cfg.block_s).astype(int)
        first = int(rng.integers(2))
        train, held = np.flatnonzero(block % 2 == first), np.flatnonzero(block % 2 != first)
        if train.size == 0 or held.size == 0:
            raise IdentificationError("the episode's free motion spans no two "
                                      f"{self.inner.cfg.block_s} s blocks to train and hold out")
        self.inner.pin_tare_knots(self.keep[train])
        self.baseline = self.inner.baseline
        if self.slides is not None:  # alternate insertions: other holes than the fit saw
            k = np.arange(self.slides.n)
            train = np.r_[train, self.n_arm + k[k % 2 == first]]
            held = np.r_[held, self.n_arm + k[k % 2 != first]]
        return train, held

    def locate(self, rows: NDArray[np.int64], whitened: Vec) -> list[LocateRow]:
        arm, w_arm, w_slides = self._split_whitened(rows, whitened)
        out = self.inner.locate(self.keep[arm], w_arm)
        if w_slides.size:
            out += locate_rows([("insertion force ratio", "phase", "chamfer slide", w_slides)])
        return out


def free_windows(rec: Recording, inner: ArmDynamicsFamily) -> tuple[NDArray[np.int64], dict[str, int]]:
    """Rows of ``inner`` whose whole window lies inside one free-motion phase, and the count of
    the others per phase (a window straddling two phases counts for the first)."""
    keep, excluded, _ = free_windows_by_phase(rec, inner)
    return keep, excluded


def free_windows_by_phase(rec: Recording, inner: ArmDynamicsFamily
                          ) -> tuple[NDArray[np.int64], dict[str, int], NDArray[np.str_]]:
    """:func:`free_windows`, and the phase each kept row lies in."""
    t = inner.terms
    half_s = t.rows.half / float(rec.meta.sample_rate_hz)
    lo, hi = t.time - half_s, t.time + half_s
    keep = np.zeros(len(t.time), bool)
    where = np.full(len(t.time), "", dtype=object)
    phase = np.full(len(t.time), "", dtype=object)
    for p in rec.meta.phases:
        inside = (lo >= p.start) & (hi <= p.end)
        touches = (hi >= p.start) & (lo <= p.end) & (where == "")
        where[touches] = p.name
        if p.name in FREE_PHASES:
            keep |= inside
            phase[inside] = p.name
    excluded: dict[str, int] = {}
    for name in where[~keep]:
        excluded[name or "outside every phase"] = excluded.get(name or "outside every phase", 0) + 1
    rows = np.flatnonzero(keep)
    return rows, excluded, phase[rows].astype(str)


def family_from_recording(rec: Recording, cfg: ArmDynamicsConfig | None = None) -> EpisodeFamily:
    """The episode family of ``rec`` (IdentificationError names what the recording lacks)."""
    # a state restore after a sim fault leaves a gap of one period (tasks/episode_recorder.py)
    inner = dynamics_family(rec, cfg or ArmDynamicsConfig(tare_knot_s=TARE_KNOT_S),
                            breaks_allowed=True)
    keep, excluded, phases = free_windows_by_phase(rec, inner)
    return EpisodeFamily(inner, keep, excluded, chamfer_slides(rec), phases)
