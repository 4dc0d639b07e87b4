"""serpar's layers (pyproject.toml [tool.importlinter], docs/layout.md): every module imports
only from the layers below it, and the contract catches a back edge."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import serpar

REPO = Path(__file__).resolve().parents[1]
PACKAGE = Path(serpar.__file__).resolve().parent


def _lint_imports(cwd: Path, pythonpath: Path | None = None) -> subprocess.CompletedProcess:
    env = None
    if pythonpath is not None:
        env = {**os.environ, "PYTHONPATH": str(pythonpath)}
    cmd = [sys.executable, "-c", ("import sys; from importlinter.cli import lint_imports_command; "
                                  "sys.exit(lint_imports_command())"), "--no-cache"]
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, check=False, timeout=120)


def test_layers_contract_is_kept():
    result = _lint_imports(REPO)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "1 kept, 0 broken" in result.stdout


def test_a_back_edge_breaks_the_contract(tmp_path):
    """sim importing the task (a layer above it) must fail the contract."""
    copy = tmp_path / "serpar"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns(
        ".*", "__pycache__", "tests", "docs", "*.png", "*.jpg", "*.xml", "*.csv", "*.md", "*.egg-info", "build"))
    with (copy / "sim" / "scene.py").open("a") as f:
        f.write("\nimport serpar.tasks.episode  # noqa: E402  (a deliberate back edge)\n")
    shutil.copy(REPO / "pyproject.toml", tmp_path / "pyproject.toml")
    result = _lint_imports(tmp_path, pythonpath=tmp_path)
    assert result.returncode != 0, result.stdout
    assert "serpar.sim is not allowed to import serpar.tasks" in result.stdout
    assert "serpar.sim.scene -> serpar.tasks.episode" in result.stdout


@pytest.mark.parametrize("name", ["sim", "tasks", "controllers", "vision", "assets", "calibration",
                                  "diagnosis", "twins", "checks", "kinematics", "cli", "identify"])
def test_serpar_installs_one_top_level_name(name):
    """A repository folder is never importable as a top-level name, even from the repository root."""
    result = subprocess.run([sys.executable, "-c", f"import {name}"], cwd=REPO, capture_output=True,
                            text=True, check=False, timeout=60)
    assert result.returncode != 0
    assert "ModuleNotFoundError" in result.stderr
