"""Stewart workspace Monte Carlo (seed 000 §4.1), its plot and the ``workspace`` command."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from serpar.checks.workspace import l_min_scan, workspace_monte_carlo
from serpar.checks.workspace_plot import plot_workspace
from serpar.cli.cmd_workspace import register
from serpar.errors import ConfigError
from serpar.kinematics.stewart_kinematics import LIMIT_NAMES, limit_violations
from serpar.kinematics.stewart_table import table_geometry
from serpar.sim.stewart import stewart_geometry

GEOM = stewart_geometry()


@pytest.fixture(scope="module")
def full() -> dict[str, tuple]:
    return {d: workspace_monte_carlo(GEOM, 200_000, seed=0, definition=d)
            for d in ("deflection", "normal")}


def test_fraction_of_20k_matches_200k_within_statistics(full: dict[str, tuple]) -> None:
    for definition, (big, points) in full.items():
        small, _ = workspace_monte_carlo(GEOM, 20_000, seed=1, definition=definition)
        sigma = np.hypot(small.fraction_std, big.fraction_std)
        assert abs(small.fraction - big.fraction) < 4 * sigma, (definition, small, big)
        assert points.shape == (big.valid, 3)


def test_breakdown_is_consistent(full: dict[str, tuple]) -> None:
    deflection, normal = full["deflection"][0], full["normal"][0]
    for r in (deflection, normal):
        assert r.samples == 200_000 and set(r.rejected) == set(LIMIT_NAMES)
        assert r.valid + max(r.rejected.values()) <= r.samples
        assert all(r.only[k] <= r.rejected[k] for k in LIMIT_NAMES)
    # The stroke checks do not depend on the hinge definition; the plate-normal one is stricter.
    for k in ("stroke_low", "stroke_high"):
        assert deflection.rejected[k] == normal.rejected[k]
    assert normal.valid < deflection.valid
    # Measured (seed 0): far below the seed's 68.3 % (see assets/stewart/README.md).
    assert 0.19 < deflection.fraction < 0.23 and 0.05 < normal.fraction < 0.07


def test_valid_points_lie_in_the_box_and_pass_limits(full: dict[str, tuple]) -> None:
    _, points = full["deflection"]
    lo, hi = points.min(axis=0), points.max(axis=0)
    assert np.all(lo >= [-0.1, -0.1, 0.23]) and np.all(hi <= [0.1, 0.1, 0.3])


def test_home_is_valid_and_out_of_stroke_is_rejected() -> None:
    home = np.array(GEOM.home_pos)
    for definition in ("deflection", "cardan", "normal"):
        v = limit_violations(GEOM, home, np.eye(3), definition)
        assert not any(v[k].any() for k in LIMIT_NAMES), definition
    v = limit_violations(GEOM, np.array([0.0, 0.0, 0.300]), np.eye(3))  # all legs 59.5 mm
    assert v["stroke_high"].all() and not v["stroke_low"].any()
    v = limit_violations(GEOM, np.array([0.0, 0.0, 0.230]), np.eye(3))  # all legs -8.6 mm
    assert v["stroke_low"].all()


def test_l_min_scan_agrees_with_monte_carlo() -> None:
    scan = l_min_scan(GEOM, 20_000, seed=2)
    assert scan.best_fraction <= scan.hinge_ok_fraction
    assert scan.l_min_matching_paper_m == ()  # 50.8 mm of stroke cannot reach 68.3 %
    assert 0.07 < scan.stroke_for_paper_m < 0.09
    at_best = table_geometry(True, scan.best_l_min_m + 1e-12, GEOM.stroke, 20.0, 30.0, 0.265)
    r, _ = workspace_monte_carlo(at_best, 20_000, seed=2)
    assert abs(r.fraction - scan.best_fraction) <= 2 / 20_000


def test_bad_monte_carlo_input() -> None:
    with pytest.raises(ConfigError, match="samples"):
        workspace_monte_carlo(GEOM, 0)
    with pytest.raises(ConfigError, match="valid: deflection"):
        workspace_monte_carlo(GEOM, 10, definition="vertical")  # type: ignore[arg-type]


def _run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="serpar")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["workspace", *argv])
    return args.func(args)


def test_cli_json_and_plot(tmp_path, capsys) -> None:
    out = tmp_path / "ws.png"
    assert _run(["--samples", "20000", "--seed", "3", "--json", "--plot", str(out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["samples"] == 20_000 and doc["hinge_definition"] == "deflection"
    assert doc["paper_valid"] == 136_534 and 0.18 < doc["fraction"] < 0.24
    assert doc["plot"] == str(out) and out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert _run(["--samples", "5000", "--hinge-definition", "normal"]) == 0
    text = capsys.readouterr().out
    assert "68.27 %" in text and "stroke_high" in text and "'normal'" in text


@pytest.mark.parametrize("argv, match", [(["--samples", "0"], "samples"),
                                         (["--plot", "ws.jpg"], r"\.png"),
                                         (["--plot", "/no/such/dir/ws.png"], "does not exist")])
def test_cli_rejects_bad_input(argv: list[str], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        _run(argv)


def test_plot_rejects_bad_points(tmp_path) -> None:
    with pytest.raises(ConfigError):
        plot_workspace(np.zeros((4, 2)), tmp_path / "x.png")
