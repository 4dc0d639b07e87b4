"""The diagnosis engine on a small synthetic family whose truth is known exactly: forward
selection, the earn-its-parameters rule, the noise-floor stop, uncertainty, result types."""

from __future__ import annotations

import numpy as np
import pytest

from serpar.diagnosis import Effect, LocateRow
from serpar.diagnosis.findings import shares
from serpar.diagnosis.fit import fit_model
from serpar.diagnosis.locate import locate_rows
from serpar.diagnosis.select import SelectConfig, diagnose
from serpar.errors import IdentificationError

SIGMA = 0.01


class Line:
    """y(t) = offset (baseline) [+ slope t] [+ amp sin(3 t)] [+ curv t^2] + noise; held-out:
    the last third in time (extrapolation, as for a drift)."""

    kind = "synthetic"

    def __init__(self, truth: dict[str, float], seed: int = 0, n: int = 300) -> None:
        rng = np.random.default_rng(seed)
        self.t = np.linspace(0.0, 10.0, n)
        self.y = (0.3 + truth.get("slope", 0.0) * self.t
                  + truth.get("amp", 0.0) * np.sin(3 * self.t)
                  + truth.get("curv", 0.0) * self.t**2 + rng.normal(size=n) * SIGMA)
        self.n_samples = n
        self.baseline = Effect("baseline", "offset", ("offset",), ("m",), np.zeros(1),
                               np.full(1, -10.0), np.full(1, 10.0))
        self.effects = (
            Effect("slope", "linear drift", ("slope",), ("m/s",), np.zeros(1),
                   np.full(1, -1.0), np.full(1, 1.0)),
            Effect("sine", "oscillation", ("amp",), ("m",), np.zeros(1), np.full(1, -1.0),
                   np.full(1, 1.0)),
            Effect("curve", "quadratic drift", ("curv",), ("m/s2",), np.zeros(1),
                   np.full(1, -1.0), np.full(1, 1.0)))

    def residual(self, params, rows):
        t = self.t[rows]
        model = params["baseline"][0] + np.zeros_like(t)
        if "slope" in params:
            model = model + params["slope"][0] * t
        if "sine" in params:
            model = model + params["sine"][0] * np.sin(3 * t)
        if "curve" in params:
            model = model + params["curve"][0] * t**2
        return (model - self.y[rows]) / SIGMA

    def split(self, rng):
        cut = 2 * self.n_samples // 3
        return np.arange(cut), np.arange(cut, self.n_samples)

    def locate(self, rows, whitened):
        return locate_rows([("y", "time", "early", whitened[self.t[rows] < 5]),
                            ("y", "time", "late", whitened[self.t[rows] >= 5])])


def test_no_effect_is_no_missing_physics() -> None:
    d = diagnose(Line({}))
    assert d.no_missing_physics and d.findings == ()
    assert d.heldout_rms_after < 1.5
    assert not any(r.flagged for r in d.locate_before)


def test_the_true_effect_is_ranked_first_and_recovered_within_3_sigma() -> None:
    d = diagnose(Line({"slope": 0.02}))
    assert d.top_effect == "slope" and len(d.findings) == 1
    p = d.findings[0].params[0]
    assert abs(p.value - 0.02) < 3 * p.std
    assert d.heldout_rms_before > 5 and d.heldout_rms_after < 1.5
    assert d.explained > 0.95
    assert any(r.flagged for r in d.locate_before)
    as_json = d.as_dict()
    assert as_json["top_effect"] == "slope" and as_json["findings"][0]["params"][0]["std"] > 0


def test_two_effects_by_forward_selection() -> None:
    d = diagnose(Line({"slope": 0.02, "amp": 0.05}))
    assert {f.effect for f in d.findings} == {"slope", "sine"}
    assert "curve" not in {f.effect for f in d.findings}
    assert d.heldout_rms_after < 1.5


def test_values_come_from_every_row_and_held_out_figures_from_the_training_fit() -> None:
    """The split chooses and scores the model; the established values are then fitted on every
    row (least squares of offset + slope on all 300), with the smaller sigma that gives."""
    line = Line({"slope": 0.02}, seed=3)
    d = diagnose(line, cfg=SelectConfig(folds=0))
    design = np.stack([np.ones_like(line.t), line.t], axis=1)
    every, *_ = np.linalg.lstsq(design, line.y, rcond=None)
    cut = 2 * line.n_samples // 3
    train, *_ = np.linalg.lstsq(design[:cut], line.y[:cut], rcond=None)
    (slope,) = d.findings[0].params
    assert slope.value == pytest.approx(every[1], rel=1e-6)
    assert abs(slope.value - train[1]) > 1e-6  # the training fit's is another value
    assert d.model["params"]["slope"]["values"][0] == pytest.approx(every[1], rel=1e-6)
    sigma_every = SIGMA * np.sqrt(np.linalg.inv(design.T @ design)[1, 1])
    sigma_train = SIGMA * np.sqrt(np.linalg.inv(design[:cut].T @ design[:cut])[1, 1])
    assert slope.std == pytest.approx(sigma_every, rel=0.2) and slope.std < 0.8 * sigma_train
    held = design[cut:] @ train - line.y[cut:]
    assert d.heldout_rms_after == pytest.approx(np.sqrt(np.mean(held**2)) / SIGMA, rel=1e-6)


def test_a_model_that_fails_on_held_out_rows_keeps_its_training_values() -> None:
    """A quadratic drift with only the linear candidate: the held-out residual is beyond noise,
    so the slope is not refitted on rows the model cannot follow."""
    line = Line({"slope": 0.02, "curv": 0.002}, seed=3)
    line.effects = tuple(e for e in line.effects if e.name != "curve")
    d = diagnose(line, cfg=SelectConfig(folds=0))
    assert d.top_effect == "slope" and not d.residual.passes
    cut = 2 * line.n_samples // 3
    design = np.stack([np.ones_like(line.t), line.t], axis=1)
    train, *_ = np.linalg.lstsq(design[:cut], line.y[:cut], rcond=None)
    assert d.findings[0].params[0].value == pytest.approx(train[1], rel=1e-6)


def test_an_effect_must_earn_its_parameters() -> None:
    """A slope of a fifth of the noise over the whole record is not worth a parameter."""
    weak = diagnose(Line({"slope": 0.0002}, seed=2))
    assert weak.no_missing_physics


def test_max_effects_zero_reports_unexplained() -> None:
    d = diagnose(Line({"slope": 0.02}), cfg=SelectConfig(max_effects=0))
    assert not d.no_missing_physics and d.findings == ()
    assert "no candidate" in d.verdict


@pytest.mark.parametrize("kwargs", [
    {"units": ("m", "m")},
    {"x0": np.array([2.0])},
    {"lower": np.array([1.0]), "upper": np.array([0.0])},
    {"x0": np.array([np.nan])},
])
def test_effect_validation(kwargs) -> None:
    base = {"name": "e", "summary": "s", "param_names": ("a",), "units": ("m",),
            "x0": np.zeros(1), "lower": -np.ones(1), "upper": np.ones(1)}
    with pytest.raises(IdentificationError):
        Effect(**{**base, **kwargs})


def test_locate_row_flags_only_beyond_noise() -> None:
    rng = np.random.default_rng(0)
    rows = locate_rows([("a", "g", "noise", rng.normal(size=500)),
                        ("b", "g", "bias", rng.normal(size=500) + 1.0)])
    assert [r.flagged for r in rows] == [False, True]
    assert isinstance(rows[0], LocateRow) and rows[0].as_dict()["n"] == 500


class LineWithProbes(Line):
    """A long line at its noise floor and six probe rows offset by ``PROBE`` (3 sigma), which
    only the ``probe`` effect explains: a small independent part of the data (an episode's
    chamfer slides beside its arm rows)."""

    PROBE = 0.03

    def __init__(self, parts: bool) -> None:
        super().__init__({}, seed=3, n=3000)
        self.n_line, self.n_samples = self.n_samples, self.n_samples + 6
        self.effects = self.effects + (Effect("probe", "probe offset", ("d",), ("m",),
                                              np.zeros(1), np.full(1, -1.0), np.full(1, 1.0)),)
        self.probe_noise = np.random.default_rng(4).normal(size=6) * SIGMA
        if parts:
            self.residual_parts = lambda rows, w: {"line": w[rows < self.n_line],
                                                   "probes": w[rows >= self.n_line]}

    def residual(self, params, rows):
        rows = np.asarray(rows)
        line, probe = rows[rows < self.n_line], rows[rows >= self.n_line] - self.n_line
        d = params["probe"][0] if "probe" in params else 0.0
        probes = (d - self.PROBE - self.probe_noise[probe]) / SIGMA
        return np.r_[super().residual({k: v for k, v in params.items() if k != "probe"}, line),
                     probes]

    def split(self, rng):
        cut = 2 * self.n_line // 3
        train, held = np.arange(cut), np.arange(cut, self.n_line)
        k = self.n_line + np.arange(6)
        return np.r_[train, k[::2]], np.r_[held, k[1::2]]

    def locate(self, rows, whitened):
        rows = np.asarray(rows)
        return locate_rows([("y", "time", "line", whitened[rows < self.n_line]),
                            ("probe", "row", "probes", whitened[rows >= self.n_line])])


def test_a_small_part_beyond_noise_keeps_selection_going() -> None:
    """The whole held-out residual is at its noise floor (three 3-sigma rows among a thousand),
    but the probes alone are not: selection goes on for them only where the family names them
    as a part of their own."""
    assert "probe" not in {f.effect for f in diagnose(LineWithProbes(parts=False)).findings}
    d = diagnose(LineWithProbes(parts=True))
    assert [f.effect for f in d.findings] == ["probe"]
    (p,) = d.findings[0].params
    assert abs(p.value - LineWithProbes.PROBE) < 3 * p.std
    # with no candidate allowed, the probes beyond noise still keep "no missing physics" away
    assert diagnose(LineWithProbes(parts=False), cfg=SelectConfig(max_effects=0)).no_missing_physics
    unexplained = diagnose(LineWithProbes(parts=True), cfg=SelectConfig(max_effects=0))
    assert not unexplained.no_missing_physics and "no candidate" in unexplained.verdict


def test_an_effect_on_a_small_part_is_judged_on_that_part() -> None:
    """The line's held-out rows read 0.9 sigma, so the whole held-out residual is under its
    noise floor; the probe effect still removes what the probes hold above it, and its share of
    what was left is judged on them (not 0 % of a clipped whole)."""
    fam = LineWithProbes(parts=True)
    fam.y = 0.3 + 0.9 * (fam.y - 0.3)
    train, held = fam.split(np.random.default_rng(0))
    path = [fit_model(fam, (), train, held), fit_model(fam, ("probe",), train, held)]
    assert path[0].heldout_chi2 < path[0].n_heldout  # the whole: under the floor
    assert shares(fam, path, held)["probe"][1] > 0.9


class TwinLines(Line):
    """Line with a second candidate, ``creep``, whose shape is the slope's over these data
    (c (t + 0.001 sin(t)): a creep the data cannot tell from a drift)."""

    tells_rivals = True

    def __init__(self, truth: dict[str, float], seed: int = 0) -> None:
        super().__init__(truth, seed)
        self.effects += (Effect("creep", "creep", ("c",), ("m/s",), np.zeros(1),
                                np.full(1, -1.0), np.full(1, 1.0)),)

    def residual(self, params, rows):
        r = super().residual({k: v for k, v in params.items() if k != "creep"}, rows)
        if "creep" in params:
            t = self.t[rows]
            r = r + params["creep"][0] * (t + 1e-3 * np.sin(t)) / SIGMA
        return r


def test_two_candidates_the_data_cannot_tell_apart_are_a_or_b() -> None:
    """The drift is found, but the creep explains the held-out rows alike: "slope or creep:
    these data cannot tell", neither established, the model carrying the one selected; the
    curve, which the held-out extrapolation tells apart, is no rival of a true slope."""
    from serpar.diagnosis.rivals import vuong_z

    d = diagnose(TwinLines({"slope": 0.02}))
    assert d.established == ()
    (finding,) = d.findings
    other = ({"slope", "creep"} - {finding.effect}).pop()
    assert f"{finding.effect} or {other}" in finding.reasons[-1]
    assert "these data cannot tell" in finding.reasons[-1]
    assert f"the model carries {finding.effect}" in finding.reasons[-1]
    assert finding.effect in d.model["params"]
    clear = diagnose(Line({"slope": 0.02}))
    assert [f.effect for f in clear.established] == ["slope"]
    rng = np.random.default_rng(0)
    a = rng.normal(size=(200, 3))
    assert abs(vuong_z(a, a, 200)) == 0.0 and vuong_z(a, 2 * a, 200) > 5


class NestedLines(Line):
    """Line with ``wobbly``: the slope plus two columns of its own (t, sin 40t, cos 40t): a
    candidate that holds the slope as a special case."""

    def __init__(self, truth: dict[str, float], seed: int = 0) -> None:
        super().__init__(truth, seed)
        self.y = self.y + truth.get("wobble", 0.0) * np.sin(40 * self.t)
        self.effects += (Effect("wobbly", "slope and wobble", ("slope", "a", "b"), ("m/s", "m", "m"),
                                np.zeros(3), np.full(3, -1.0), np.full(3, 1.0)),)

    def residual(self, params, rows):
        r = super().residual({k: v for k, v in params.items() if k != "wobbly"}, rows)
        if "wobbly" in params:
            t = self.t[rows]
            s, a, b = params["wobbly"]
            r = r + (s * t + a * np.sin(40 * t) + b * np.cos(40 * t)) / SIGMA
        return r


def test_of_two_candidates_that_fit_alike_the_one_with_fewer_parameters_is_selected() -> None:
    """A wobble too small to pay for its two parameters on the held-out rows (it lowers their
    chi-square by a few units, below 2 ln n): the slope is selected, not the candidate that
    holds it with the wobble; a wobble large enough to pay its price selects that one."""
    fam = NestedLines({"slope": 0.02, "wobble": 0.003}, seed=3)
    train, held = fam.split(None)
    with_slope = fit_model(fam, ("slope",), train, held)
    with_wobble = fit_model(fam, ("wobbly",), train, held)
    gain = with_slope.heldout_chi2 - with_wobble.heldout_chi2
    assert 0 < gain < 2 * np.log(held.size)  # it fits the held-out rows better, not by its price
    assert [f.effect for f in diagnose(fam).findings][:1] == ["slope"]
    big = diagnose(NestedLines({"slope": 0.02, "wobble": 0.01}))
    assert [f.effect for f in big.findings][:1] == ["wobbly"]
