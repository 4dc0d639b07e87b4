"""No silent overwrite (issue 26 B): every command that writes refuses an existing output
unless --force, and finds an output it cannot write before any work, in one line, exit 2."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from serpar.cli.entry import main
from serpar.sim.recording import read_recording


def csv_file(folder: Path, rows: int = 50) -> Path:
    path = folder / "log.csv"
    t = np.arange(rows) * 1e-3
    path.write_text("time,q1\n" + "".join(f"{a:.3f},{0.1 * a:.6f}\n" for a in t))
    return path


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("serpar: error: ") and "Traceback" not in err, err
    return lines[0]


def refused(argv: list[str], capsys, path: Path) -> str:
    assert main(argv) == 2
    line = one_error_line(capsys)
    assert str(path) in line and "--force" in line, line
    return line


def test_import_refuses_an_existing_recording_and_force_replaces_it(tmp_path, capsys) -> None:
    src, out = csv_file(tmp_path), tmp_path / "rec"
    assert main(["import", str(src), "--out", str(out)]) == 0
    (out / "measurements.parquet").write_text("a stale table of an earlier import")
    before = (out / "meta.json").read_text()
    refused(["import", str(src), "--out", str(out)], capsys, out)
    assert (out / "meta.json").read_text() == before
    assert main(["import", str(src), "--out", str(out), "--force", "--rate", "1000"]) == 0
    assert not (out / "measurements.parquet").exists()  # no stale table mixed into the new recording
    assert read_recording(out).signals.num_rows == 50
    assert main(["import-csv", str(src), "--out", str(tmp_path / "empty_is_fine")]) == 0


def test_twin_refuses_an_existing_output_and_force_replaces_it(tmp_path, capsys) -> None:
    out = tmp_path / "twin"
    out.mkdir()
    (out / "answer.json").write_text("{}")
    refused(["twin", "--effect", "none", "--out", str(out)], capsys, out)
    assert main(["twin", "--effect", "none", "--out", str(out), "--force"]) == 0
    assert json.loads((out / "answer.json").read_text())["effect"] == "none"
    read_recording(out)


def test_render_refuses_an_existing_png_before_rendering_and_force_replaces_it(tmp_path, capsys) -> None:
    out = tmp_path / "x.png"
    out.write_bytes(b"old")
    refused(["render", "--camera", "overview", "--out", str(out)], capsys, out)
    assert out.read_bytes() == b"old"
    assert main(["render", "--camera", "overview", "--out", str(out), "--width", "160", "--height", "120",
                 "--force"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_run_record_refuses_an_existing_episode_folder_at_once(tmp_path) -> None:
    """Before any calibration or episode: a subprocess, so nothing is cached in-process."""
    (tmp_path / "rec" / "episode_0").mkdir(parents=True)
    r = subprocess.run([sys.executable, "-m", "serpar", "run", "--holes", "1", "--record", str(tmp_path / "rec")], check=False,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stdout == ""
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and str(tmp_path / "rec" / "episode_0") in lines[0] and "--force" in lines[0]


@pytest.mark.parametrize("argv, name", [
    (["diagnose", "REC", "--report", "{out}"], "r.html"),
    (["calibrate", "stewart", "--out", "{out}"], "p.json"),
    (["workspace", "--samples", "1000", "--plot", "{out}"], "w.png"),
])
def test_other_file_outputs_are_refused_before_any_work(tmp_path, capsys, argv, name) -> None:
    out = tmp_path / name
    out.write_text("old")
    refused([a.replace("{out}", str(out)).replace("REC", str(tmp_path)) for a in argv], capsys, out)
    assert out.read_text() == "old"


@pytest.mark.parametrize("argv", [
    ["error-analysis", "--samples", "1000", "--plot", "{out}"],
    ["vision-check", "--overlay", "{out}"],
    ["calibrate", "stewart", "--plot", "{out}"],
])
def test_plot_folders_that_hold_files_are_refused(tmp_path, capsys, argv) -> None:
    out = tmp_path / "plots"
    out.mkdir()
    (out / "old.png").write_text("old")
    refused([a.replace("{out}", str(out)) for a in argv], capsys, out)


def unwritable_cases(tmp_path: Path) -> list[tuple[Path, str]]:
    """Output paths this process cannot write: under a regular file (always); in /proc (Linux,
    even as root); in a read-only folder (only where permissions bind: not as root)."""
    (tmp_path / "file").write_text("x")
    cases = [(tmp_path / "file" / "out", "is not a folder")]
    if Path("/proc/self").is_dir():
        cases.append((Path("/proc/serpar_out"), "cannot write in /proc"))
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    if not os.access(ro, os.W_OK):
        cases.append((ro / "out", "cannot write in"))
    return cases


@pytest.mark.parametrize("command", ["render", "import", "twin", "run", "diagnose"])
def test_an_output_that_cannot_be_written_fails_first_in_one_line(tmp_path, capsys, command) -> None:
    src = csv_file(tmp_path)
    for out, why in unwritable_cases(tmp_path):
        argv = {"render": ["render", "--camera", "overview", "--out", f"{out}.png"],
                "import": ["import", str(src), "--out", str(out)],
                "twin": ["twin", "--effect", "none", "--out", str(out)],
                "run": ["run", "--holes", "1", "--record", str(out)],
                "diagnose": ["diagnose", str(tmp_path), "--report", f"{out}.html"]}[command]
        assert main(argv) == 2
        line = one_error_line(capsys)
        assert str(out) in line and why in line, line
    (tmp_path / "ro").chmod(0o755)
