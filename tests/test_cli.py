"""The command line: figures, images, and one-line errors with exit code 2."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from serpar.cli.entry import build_parser, main


def run(*args: str) -> subprocess.CompletedProcess:
    # the tests read the exit code themselves: a failing command is what some of them expect
    return subprocess.run([sys.executable, "-m", "serpar", *args], capture_output=True, text=True,
                          timeout=300, check=False)


@pytest.mark.parametrize("args, needle", [
    (["render", "--camera", "nope", "--out", "x.png"], "valid: overview, top_left"),
    (["info", "--seed", "abc"], "invalid int value"),
    (["render", "--camera", "top_left", "--out", "x.png", "--width", "5000"], "out of range"),
    (["render", "--camera", "top_left", "--out", "x.png", "--width", "640", "--height", "640"], "4:3"),
    (["validate", "--check", "bogus"], "valid: rim_rest"),
    (["frobnicate"], "invalid choice"),
    (["vision-check", "--width", "300"], "invalid choice: 300"),
    (["vision-check", "--poses", "0"], "platform_poses >= 1"),
    (["bench", "--repeats", "0"], "repeats in 1..20"),
    (["run", "--holes", "0"], "a count in 1..36"),
    (["run", "--episodes", "0"], "--episodes 0: must be >= 1"),
    (["run", "--workers", "0"], "--workers 0: must be >= 1"),
    (["ablate", "--holes", "37"], "a count in 1..36"),
    (["ablate", "--episodes", "0"], "both must be >= 1"),
])
def test_bad_input_is_one_line_exit_2(args, needle):
    r = run(*args)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in r.stderr


def test_malformed_config_is_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("seed: 1\nn_conductor: 3\n")
    r = run("info", "--config", str(bad))
    assert r.returncode == 2 and "unknown key(s) n_conductor" in r.stderr
    bad.write_text("seed: [1, 2\n")
    r = run("info", "--config", str(bad))
    assert r.returncode == 2 and "not valid YAML" in r.stderr and len(r.stderr.splitlines()) == 1


def test_info_json_reports_drawn_diameters(capsys):
    assert main(["info", "--json", "--seed", "5"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["seed"] == 5 and len(info["holes_um"]) == 36 and len(info["journals_um"]) == 36
    assert all(1700.0 <= h <= 1710.0 for h in info["holes_um"])
    assert all(1694.0 <= j <= 1700.0 for j in info["journals_um"])
    assert info["timestep_s"] == pytest.approx(1e-4)


def test_render_top_camera_sees_plate_and_tray(tmp_path):
    out = tmp_path / "top.png"
    assert main(["render", "--camera", "top_left", "--out", str(out), "--width", "512"]) == 0
    img = np.asarray(Image.open(out))
    assert img.shape == (384, 512, 3)
    # Brass conductors (yellow: R > B) and the blue tray are both in view.
    r, g, b = (img[..., i].astype(int) for i in range(3))
    assert ((r - b > 60) & (g > 80)).sum() > 50
    assert (b - r > 60).sum() > 500


def test_validate_json_subset(capsys):
    assert main(["validate", "--json", "--check", "rim_rest"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["passed"] and out["checks"][0]["name"] == "rim_rest"


@pytest.mark.parametrize("camera", ["inspect_left", "inspect_right"])
def test_in_hand_cameras_see_the_journal_against_the_backlight(tmp_path, camera):
    out = tmp_path / "inspect.png"
    assert main(["render", "--state", "inspect", "--camera", camera, "--out", str(out),
                 "--width", "640"]) == 0
    img = np.asarray(Image.open(out)).astype(int)
    brass = (img[..., 0] - img[..., 2] > 25) & (img[..., 0] > 60)
    backlight = img.min(axis=2) > 240
    assert brass.sum() > 300 and backlight.mean() > 0.3
    # The part hangs near the image centre (the pair converges on the inspection point).
    cols = np.nonzero(brass.any(axis=0))[0]
    assert abs(cols.mean() - 320) < 80


def test_render_state_rejects_unknown():
    r = run("render", "--state", "flying", "--camera", "overview", "--out", "x.png")
    assert r.returncode == 2 and "valid: home, inspect" in r.stderr


def test_the_usage_line_names_every_command() -> None:
    """The command list in `serpar --help`'s usage is every registered command by its own name
    (a hand-written list had lost export-mjcf and sim2real); aliases are not in it."""
    parser = build_parser()
    usage = parser.format_usage()
    listed = set(re.search(r"\{([^}]*)\}", usage).group(1).split(","))
    sub = next(a for a in parser._actions if a.dest == "command")
    assert listed == {a.dest for a in sub._choices_actions}
    assert {"export-mjcf", "sim2real", "diagnose", "run"} <= listed
    assert "import-csv" not in listed and "import-csv" in sub.choices
