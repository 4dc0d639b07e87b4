"""A link's mass in an assembly episode is established only where two free-motion phases each
show it and agree on it (diagnosis/phase_consistency.py), on a synthetic family whose truth is
known exactly: the engine's own selection, resampling and assessment run unchanged."""

from __future__ import annotations

import numpy as np

from serpar.diagnosis import Effect
from serpar.diagnosis.select import diagnose
from serpar.diagnosis.stability import default_folds

SIGMA = 0.01
PHASES = ("register", "locate", "inspect")


class Moves:
    """Rows in three phases of 400 rows each; each row's load l (a link's gravity and inertia
    at that move) and a second load u that only the inspect phase has (physics no candidate
    holds). y = m_true l + k_true u + noise; the candidate ``link_inertia`` fits m l."""

    kind = "synthetic moves"
    phase_checked = ("link_inertia",)

    def __init__(self, mass: dict[str, float], seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        n = 400 * len(PHASES)
        self.n_samples = n
        self.row_phases = np.repeat(PHASES, 400)
        t = np.arange(n) * 0.01
        self.load = np.sin(2.1 * t) + 0.5 * np.cos(5.3 * t)
        m = np.array([mass.get(p, 0.0) for p in self.row_phases])
        self.y = m * self.load + rng.normal(size=n) * SIGMA
        self.baseline = Effect("baseline", "offset", ("offset",), ("N m",), np.zeros(1),
                               np.full(1, -10.0), np.full(1, 10.0))
        self.effects = (Effect("link_inertia", "a link's mass", ("link4",), ("",),
                               np.zeros(1), np.full(1, -0.9), np.full(1, 2.0)),)

    def residual(self, params, rows):
        model = params["baseline"][0] + params.get("link_inertia", np.zeros(1))[0] * self.load[rows]
        return (model - self.y[rows]) / SIGMA

    def split(self, rng):
        block = (np.arange(self.n_samples) // 50) % 2
        return np.flatnonzero(block == 0), np.flatnonzero(block == 1)

    def folds(self, k):
        return default_folds(self.n_samples, k)

    def locate(self, rows, whitened):
        return []


def _finding(mass: dict[str, float]):
    (finding,) = diagnose(Moves(mass)).findings
    assert finding.effect == "link_inertia"
    return finding


def test_a_mass_every_phase_shows_alike_is_established() -> None:
    finding = _finding({p: 0.1 for p in PHASES})
    assert finding.established, finding.reasons
    assert abs(finding.params[0].value - 0.1) < 3 * finding.params[0].std


def test_a_mass_only_one_phase_shows_is_suspected_with_why() -> None:
    finding = _finding({"inspect": 0.1})
    assert not finding.established
    (why,) = finding.reasons
    assert "holds in 1 of the 3 free-motion phases fitted alone (inspect of" in why


def test_phases_that_disagree_on_the_mass_leave_it_suspected() -> None:
    finding = _finding({"register": 0.1, "locate": 0.1, "inspect": 0.02})
    assert not finding.established
    (why,) = finding.reasons
    assert "differ by" in why and "inspect" in why and "link4" in why
