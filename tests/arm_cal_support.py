"""Shared pieces of the arm calibration tests (MD-H and POE forms)."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np

from serpar.calibration.arm_calibration import calibrate, identifiability_of
from serpar.calibration.arm_error_models import (
    ArmModel,
    chain_forward,
    initial_parameters,
    layout,
    predict,
)
from serpar.calibration.poe_design import tool_ik
from serpar.sim.arm import Q_MAX, Q_MIN
from serpar.sim.arm_measurements import PointSet, PositionSet

TOOL = (0.01, 0.05, 0.12)
REAL = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "panda_1"
PUBLISHED_EXTRAS = ("comments.txt", "back-high/hole_0_pose.csv", "front/comments.txt",
                    "front/README.md", "photos/")
"""What a published copy of panda_1 carries besides the socket files (the loader's notes name
each; a folder ends in /)."""
LO, HI = np.asarray(Q_MIN) + 0.1, np.asarray(Q_MAX) - 0.1


def poses(n: int, seed: int) -> np.ndarray:
    """Random joint angles 0.1 rad inside the limits."""
    return np.random.default_rng(seed).uniform(LO, HI, size=(n, 7))


def gravity_like_load(q: np.ndarray) -> np.ndarray:
    """A smooth configuration-dependent load of the size of the Panda's gravity torques,
    zero on joint 1 as for a level base."""
    return np.column_stack([np.zeros(len(q)), 40 * np.sin(q[:, 1]), 5 * np.cos(q[:, 2]),
                            20 * np.sin(q[:, 3]), 2 * np.sin(q[:, 4]), 3 * np.cos(q[:, 5]),
                            0.5 * np.sin(q[:, 6])])


def truth(model: ArmModel, meas, seed: int) -> np.ndarray:
    """Errors on the identifiable parameters only (the others are not recoverable)."""
    rep = identifiability_of(model, meas)
    x = initial_parameters(model, meas)
    rng = np.random.default_rng(seed)
    for i in rep.independent:
        name = rep.names[i]
        if name.startswith("socket"):
            continue
        scale = 1e-4 if name.startswith("c") else (5e-4 if ".t" in name or name[-2:] in (
            ".a", ".d") else 1e-3)
        x[i] += rng.normal() * scale
    return x


def position_set(model: ArmModel, x: np.ndarray, q: np.ndarray, sigma: float = 15e-6,
                 noise: float = 0.0, seed: int = 0) -> PositionSet:
    """Tracker positions of the tool point under the gravity-like load."""
    lay = layout(model, PositionSet(q, np.zeros((len(q), 3)), tau_gravity=gravity_like_load(q)))
    p = predict(model, x, lay, q, gravity_like_load(q))[:, :3, 3]
    p = p + np.random.default_rng(seed).normal(size=p.shape) * noise
    return PositionSet(q, p, sigma, gravity_like_load(q))


def point_set(model: ArmModel, chain_errors: np.ndarray, counts, seed: int,
              ik: Callable = tool_ik) -> tuple[PointSet, np.ndarray]:
    """Consistent sockets of a known true chain: each socket's poses reach one point."""
    rng = np.random.default_rng(seed)
    values = model.chain.values(chain_errors)
    q, ids, centres = [], [], []
    for s, n in enumerate(counts):
        target = chain_forward(model.chain, values, rng.uniform(LO, HI)[None])[0, :3, 3]
        found = np.zeros((0, 7))
        while len(found) < n:
            sol = ik(model.chain, values, target, rng.uniform(LO, HI, size=(2 * n, 7)))
            found = np.vstack([found, sol[np.all(np.isfinite(sol), axis=1)]])
        q.append(found[:n])
        ids.append(np.full(n, s))
        centres.append(target)
    c = np.array(centres)
    return PointSet(np.vstack(q), np.concatenate(ids),
                    ((0, 1, float(np.linalg.norm(c[0] - c[1]))),)), c


def assert_noisy_estimates_within_3_sigma(model: ArmModel) -> None:
    """150 noisy tracker positions (15 um): the residual matches the stated noise and every
    identifiable parameter lies within 3 sigma of the estimator's covariance."""
    q = poses(150, 8)
    design = position_set(model, np.zeros(layout(model, PositionSet(
        q, np.zeros((150, 3)))).size), q)
    x = truth(model, design, seed=9)
    cal = calibrate(model, position_set(model, x, q, noise=15e-6, seed=10))
    ind = np.asarray(cal.report.independent)
    z = (cal.x - x)[ind] / np.sqrt(np.diag(cal.covariance))
    assert 0.8 < cal.residual_rms < 1.2        # the stated noise explains the residuals
    assert np.abs(z).max() < 3.0, [cal.names[i] for i in ind[np.abs(z) >= 3]]


def assert_recovered_exactly(model: ArmModel, meas, x: np.ndarray) -> None:
    """Noise-free measurements: the calibration returns the true socket centres and errors."""
    cal = calibrate(model, meas)
    k = 3 * cal.layout.n_points                            # socket centres first, then errors
    assert np.linalg.norm(cal.x[k:] - x[k:]) <= 1e-9 * np.linalg.norm(x[k:])
    assert np.linalg.norm(cal.x[:k] - x[:k]) <= 1e-9 * max(np.linalg.norm(x[:k]), 1.0)


def published_copy(dest: Path, drop: tuple[str, ...] = ()) -> tuple[Path, tuple[str, ...]]:
    """panda_1 (read-only, so copied) as a publication would carry it: PUBLISHED_EXTRAS added,
    the placements in ``drop`` removed. Returns the copy's folder and the extras it holds."""
    root = dest / "panda_1"
    shutil.copytree(REAL, root, ignore=shutil.ignore_patterns(*drop))
    for path in (root, *root.rglob("*")):
        path.chmod(0o755 if path.is_dir() else 0o644)
    extras = tuple(e for e in PUBLISHED_EXTRAS if e.split("/")[0] not in drop)
    for extra in extras:
        if extra.endswith("/"):
            (root / extra).mkdir()
            (root / extra / "socket_front.jpg").write_bytes(b"\xff\xd8")
        else:
            (root / extra).write_text("0.1,0.2,0.3\n" if extra.endswith(".csv") else "notes\n")
    return root, extras


def static_position_recording(robot_file: str, folder: Path) -> Path:
    """A simulated static position campaign (60 train, 40 verify poses) of the arm of
    ``robot_file``, written as a recording in ``folder``."""
    from serpar.calibration.arm_static_data import StaticArmData, to_recording
    from serpar.sim.plants.static_arm import GeometricCampaignConfig, run_geometric_campaign
    from serpar.sim.recording import write_recording
    from serpar.sim.robot_file import load_robot

    robot = load_robot(robot_file)
    cfg = GeometricCampaignConfig(n_train=60, n_verify=40)
    camp = run_geometric_campaign(robot, cfg)
    data = StaticArmData(np.vstack([camp.train.q, camp.verify.q]), "position",
                         cfg.tracker_sigma_m,
                         position=np.vstack([camp.train.position, camp.verify.position]),
                         split=np.array(["train"] * 60 + ["verify"] * 40),
                         tool_offset_m=cfg.tool_offset_m, robot=robot)
    return write_recording(folder, to_recording(data, "sim"))
