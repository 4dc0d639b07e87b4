"""The Staubli TX40's published identification against its CAD model on the real recording:
per-joint RMS [N m] of measured minus predicted drive torque, on a fitting span and a later one.

``python -m serpar.checks.tx40_published REC [--json]`` (REC: ``serpar import`` with
docs/examples/tx40_import.yaml) prints the table.

The published model (FIGAROH, ../shared/realdata/staubli_tx40/published/TX40_bp_5.csv) is
tau = Y(q, dq, ddq) phi + Ia_j ddq_j + fv_j dq_j + fs_j sign(dq_j) + off_j, plus the coupled wrist
as FIGAROH's ``_add_coupling`` writes it (figaroh-examples, staubli_tx40_tools.py): joint 5 gets
Iam6 ddq6 + fvm6 dq6 + fsm6 sign(dq5 + dq6), joint 6 gets Iam6 ddq5 + fvm6 dq5 + fsm6
sign(dq5 + dq6) (motor 6 turns with q5 + q6). phi is the min-norm standard-parameter vector whose
base combinations equal the published values; rotor inertias only inside a group (Ia1, Ia2)
are held at zero (their share is in the group's value). Any such phi gives the same Y phi:
:func:`frame_check` verifies it with the CAD parameters (MuJoCo's link frames are FIGAROH's).

Signals: every channel (q and tau) low-pass filtered at 100 Hz (Butterworth order 4, zero phase:
scipy filtfilt, as FIGAROH's TX40 example filters q), velocities and accelerations by central
differences (numpy.gradient); sign(v) is 0 where |v| < 1e-3 rad/s; the RMS is over every sample
with start <= t < end.
"""

from __future__ import annotations

import argparse
import csv
import json
import re
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import mujoco
import numpy as np
from numpy.typing import NDArray
from scipy.signal import butter, filtfilt

from serpar.diagnosis.arm_dynamics_grouping import link_regressor_at
from serpar.errors import ConfigError
from serpar.sim.arm_from_file import arm_from_file
from serpar.sim.recording import Recording, read_recording
from serpar.sim.rigid_arm import ArmDynamics

Vec = NDArray[np.float64]

_TX40 = Path("shared") / "realdata" / "staubli_tx40"


def _default_data() -> Path:
    """The staubli_tx40 folder beside a source checkout, else beside the working directory
    (an installed package lives in site-packages, away from ../shared)."""
    places = (Path(__file__).resolve().parents[2], Path.cwd().parent, Path.cwd())
    return next((p / _TX40 for p in places if (p / _TX40).is_dir()), places[-1].parent / _TX40)


DATA = _default_data()
URDF = Path("urdf") / "tx40_mdh_modified.urdf"
PUBLISHED = Path("published") / "TX40_bp_5.csv"
N_JOINTS = 6
CUTOFF_HZ = 100.0
BUTTER_ORDER = 4
DEAD_BAND = 1e-3
"""|v| below this [rad/s] gives sign(v) = 0."""
SPANS: tuple[tuple[float, float], ...] = ((0.1, 6.0), (6.0, 7.5))
"""[s] The authors fitted on 0.1-7.5 s: the second span is inside their fit too."""
STANDARD = ("m", "mx", "my", "mz", "Ixx", "Iyy", "Izz", "Ixy", "Ixz", "Iyz")
"""The columns per link of :func:`link_regressor_at` (about the link frame's origin)."""
WRIST = (4, 5)
"""0-based: joint 5 and the joint 6 whose motor turns with joint 5 (Iam6, fvm6, fsm6)."""
FRAME_TOL = 1e-6
SANE_SHARE = 0.5
"""Sanity: the published RMS under this share of the CAD model's on every joint of span 1."""

_STANDARD_NAME = re.compile(r"(Ixx|Ixy|Ixz|Iyy|Iyz|Izz|mx|my|mz|m)(\d)")
_DRIVE_NAME = re.compile(r"(fv|fs|off|Ia)\d|Iam6|fvm6|fsm6")
_TERM = re.compile(r"\s*([+-])?\s*(?:(\d+(?:\.\d*)?(?:[eE][+-]?\d+)?)\s*\*\s*)?"
                   r"((?:Ixx|Ixy|Ixz|Iyy|Iyz|Izz|mx|my|mz|m|Iam|fvm|fsm|Ia|fv|fs|off)\d)\s*")


@dataclass(frozen=True)
class BaseRow:
    """One row of TX40_bp_5.csv: the expression, its terms and the published values."""

    name: str
    terms: dict[str, float]
    ols: float
    ols_std_pct: float
    wls: float
    wls_std_pct: float


def parse_expression(text: str) -> dict[str, float]:
    """``Izz1 + 1.0*Ia1 - 0.225*m4`` -> {name: coefficient} (ConfigError for anything else)."""
    out: dict[str, float] = {}
    pos, text = 0, text.strip()
    while pos < len(text):
        m = _TERM.match(text, pos)
        if m is None or (pos > 0 and m.group(1) is None):
            raise ConfigError(f"cannot read the base parameter {text!r} at {text[pos:]!r}")
        coef = (float(m.group(2)) if m.group(2) else 1.0) * (-1.0 if m.group(1) == "-" else 1.0)
        out[m.group(3)] = out.get(m.group(3), 0.0) + coef
        pos = m.end()
    if not out:
        raise ConfigError("an empty base-parameter name")
    return out


def read_published(path: Path) -> tuple[BaseRow, ...]:
    """Every row of a FIGAROH base-parameter CSV (name, OLS, OLS std %, WLS, WLS std %)."""
    rows = []
    with open(path, newline="") as f:
        for k, rec in enumerate(csv.reader(f), start=1):
            if not rec:
                continue
            if len(rec) != 5:
                raise ConfigError(f"{path.name} row {k}: {len(rec)} fields, expected 5")
            rows.append(BaseRow(rec[0], parse_expression(rec[0]), *map(float, rec[1:])))
    return tuple(rows)


def _drive_name(row: BaseRow) -> str | None:
    """The parameter of a drive row (friction, offset, a rotor inertia alone), else None."""
    (name, coef), *rest = row.terms.items()
    return name if not rest and coef == 1.0 and _DRIVE_NAME.fullmatch(name) else None


def base_matrix(rows: tuple[BaseRow, ...], n: int = N_JOINTS
                ) -> tuple[Vec, tuple[BaseRow, ...], tuple[str, ...]]:
    """B (inertial rows x 10 n, :data:`STANDARD` order per link) with B phi = the base values,
    those rows, and the rotor inertias met inside a group (their columns left out: zero)."""
    inertial = tuple(r for r in rows if _drive_name(r) is None)
    b = np.zeros((len(inertial), 10 * n))
    grouped: set[str] = set()
    for i, row in enumerate(inertial):
        for name, coef in row.terms.items():
            m = _STANDARD_NAME.fullmatch(name)
            if m and 1 <= int(m.group(2)) <= n:
                b[i, 10 * (int(m.group(2)) - 1) + STANDARD.index(m.group(1))] += coef
            elif re.fullmatch(r"Ia\d", name):
                grouped.add(name)
            else:
                raise ConfigError(f"{name!r} in {row.name!r} is no standard parameter of "
                                  f"links 1..{n}")
    return b, inertial, tuple(sorted(grouped))


@dataclass(frozen=True)
class PublishedModel:
    """phi: 10 n standard parameters (:data:`STANDARD` order, link by link); drive: fv<j>,
    fs<j>, off<j>, the separate Ia<j>, Iam6, fvm6, fsm6; grouped_rotors: held at zero."""

    phi: Vec
    drive: dict[str, float]
    grouped_rotors: tuple[str, ...]


def published_model(rows: tuple[BaseRow, ...], values: str = "ols",
                    n: int = N_JOINTS) -> PublishedModel:
    """The min-norm phi reproducing the published base values (``ols`` or ``wls``)."""
    b, inertial, grouped = base_matrix(rows, n)
    target = np.array([getattr(r, values) for r in inertial])
    phi = np.linalg.lstsq(b, target, rcond=None)[0]
    if np.abs(b @ phi - target).max() > 1e-9 * max(1.0, float(np.abs(target).max())):
        raise ConfigError("the published base parameters are not independent combinations")
    drive = {name: float(getattr(r, values)) for r in rows if (name := _drive_name(r))}
    return PublishedModel(phi, drive, grouped)


def filtered_signals(rec: Recording, n: int = N_JOINTS) -> tuple[Vec, Vec, Vec, Vec, Vec]:
    """time, q, dq, ddq, tau (rows x n): filtered and differentiated as the module says."""
    rate = rec.meta.sample_rate_hz
    b, a = butter(BUTTER_ORDER, CUTOFF_HZ / (rate / 2))
    q, tau = (filtfilt(b, a, np.column_stack([rec.column(f"{c}{k}") for k in range(1, n + 1)]),
                       axis=0) for c in ("q", "tau_drive"))
    dq = np.gradient(q, 1.0 / rate, axis=0)
    return rec.column("time"), q, dq, np.gradient(dq, 1.0 / rate, axis=0), tau


def _sign(v: Vec) -> Vec:
    return np.where(np.abs(v) < DEAD_BAND, 0.0, np.sign(v))


def published_torque(model: PublishedModel, y: Vec, dq: Vec, ddq: Vec) -> Vec:
    """rows x n: the published model's drive torque, from the link regressor ``y`` (rows x n x
    10 n, :func:`link_regressor_at`) at the same samples."""
    tau = y @ model.phi
    d = model.drive
    for j in range(tau.shape[1]):
        k = j + 1
        tau[:, j] += (d.get(f"fv{k}", 0.0) * dq[:, j] + d.get(f"fs{k}", 0.0) * _sign(dq[:, j])
                      + d.get(f"off{k}", 0.0) + d.get(f"Ia{k}", 0.0) * ddq[:, j])
    j5, j6 = WRIST
    dry = d.get("fsm6", 0.0) * _sign(dq[:, j5] + dq[:, j6])
    tau[:, j5] += d.get("Iam6", 0.0) * ddq[:, j6] + d.get("fvm6", 0.0) * dq[:, j6] + dry
    tau[:, j6] += d.get("Iam6", 0.0) * ddq[:, j5] + d.get("fvm6", 0.0) * dq[:, j5] + dry
    return tau


def cad_parameters(dyn: ArmDynamics) -> Vec:
    """The compiled model's standard parameters (:data:`STANDARD` order, about the link origin)."""
    m = dyn.model
    out = []
    for name in dyn.arm.link_bodies:
        i = m.body(name).id
        r = np.zeros(9)
        mujoco.mju_quat2Mat(r, m.body_iquat[i])
        r, mass, c = r.reshape(3, 3), float(m.body_mass[i]), np.array(m.body_ipos[i])
        io = r @ np.diag(m.body_inertia[i]) @ r.T + mass * (c @ c * np.eye(3) - np.outer(c, c))
        out.append([mass, *(mass * c), io[0, 0], io[1, 1], io[2, 2], io[0, 1], io[0, 2], io[1, 2]])
    return np.concatenate(out)


def frame_check(dyn: ArmDynamics, rows: tuple[BaseRow, ...], y: Vec, link: Vec) -> dict[str, float]:
    """Relative errors: ``regressor`` |Y phi_cad - link torque| (column order and frames of the
    regressor); ``grouping`` |Y phi_cad - Y phi_min| with phi_min the min-norm vector of the CAD
    base values (FIGAROH's groups are exact in MuJoCo's frames). Both ~1e-6 or less when right."""
    phi = cad_parameters(dyn)
    b, _, _ = base_matrix(rows, dyn.n)
    phi_min = np.linalg.lstsq(b, b @ phi, rcond=None)[0]
    scale = float(np.abs(link).max())
    return {"regressor": float(np.abs(y @ phi - link).max()) / scale,
            "grouping": float(np.abs(y @ (phi - phi_min)).max()) / scale}


@dataclass(frozen=True)
class SpanRms:
    start: float
    end: float
    samples: int
    cad: tuple[float, ...]
    published: tuple[float, ...]


@dataclass(frozen=True)
class Comparison:
    values: str
    spans: tuple[SpanRms, ...]
    grouped_rotors: tuple[str, ...]
    frame_check: dict[str, float]
    method: str


def compare(recording: str | Path, data: Path = DATA,
            spans: tuple[tuple[float, float], ...] = SPANS, values: str = "ols") -> Comparison:
    """Per span and joint, the RMS of measured minus predicted, CAD and published model."""
    rec = read_recording(recording)
    dyn = ArmDynamics(arm=arm_from_file(str(data / URDF)))
    rows = read_published(data / PUBLISHED)
    model = published_model(rows, values, dyn.n)
    time, *signals = filtered_signals(rec, dyn.n)
    masks = [(time >= a) & (time < b) for a, b in spans]
    idx = np.flatnonzero(np.logical_or.reduce(masks))
    q, dq, ddq, tau = (x[idx] for x in signals)
    y = link_regressor_at(dyn, q, dq, ddq)
    series = dyn.series(q, dq, ddq)
    err_cad, err_pub = tau - series.full, tau - published_torque(model, y, dq, ddq)

    def rms(e: Vec) -> tuple[float, ...]:
        return tuple(np.sqrt(np.mean(e ** 2, axis=0)).round(4).tolist())

    out = [SpanRms(a, b, int(m[idx].sum()), rms(err_cad[m[idx]]), rms(err_pub[m[idx]]))
           for (a, b), m in zip(spans, masks, strict=True)]
    method = (f"q and tau low-pass {CUTOFF_HZ:g} Hz (Butterworth {BUTTER_ORDER}, filtfilt), "
              f"central differences, sign dead band {DEAD_BAND:g} rad/s, RMS over every sample")
    return Comparison(values, tuple(out), model.grouped_rotors,
                      frame_check(dyn, rows, y, series.link), method)


def sane(c: Comparison) -> bool:
    """:data:`SANE_SHARE` on the first span (inside the authors' fit), and the frames right."""
    first = c.spans[0]
    return (all(p < SANE_SHARE * k for p, k in zip(first.published, first.cad, strict=True))
            and max(c.frame_check.values()) < FRAME_TOL)


def markdown(c: Comparison) -> str:
    head = "| joint |" + "".join(f" CAD {s.start:g}–{s.end:g} s | published {s.start:g}–{s.end:g}"
                                 " s |" for s in c.spans)
    lines = [head, "|---" * (1 + 2 * len(c.spans)) + "|"]
    for j in range(len(c.spans[0].cad)):
        lines.append(f"| {j + 1} |" + "".join(f" {s.cad[j]:.3f} | {s.published[j]:.3f} |"
                                              for s in c.spans))
    fc = c.frame_check
    lines.append(f"\nRMS [N m] of measured minus predicted drive torque; published values: "
                 f"{c.values.upper()}; {c.method}.")
    lines.append(f"Held at zero inside their groups: {', '.join(c.grouped_rotors) or 'none'}. "
                 f"Frame check (relative): regressor {fc['regressor']:.1e}, grouping "
                 f"{fc['grouping']:.1e}. Sanity: {'passed' if sane(c) else 'FAILED'}.")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m serpar.checks.tx40_published",
                                     description="The TX40's published model vs its CAD "
                                     "model: per-joint torque RMS on the real recording.")
    parser.add_argument("recording", type=Path, help="folder written by serpar import")
    parser.add_argument("--data", type=Path, default=DATA,
                        help=f"the staubli_tx40 folder (default {DATA})")
    parser.add_argument("--values", choices=("ols", "wls"), default="ols")
    parser.add_argument("--json", action="store_true", help="print JSON instead of markdown")
    args = parser.parse_args(argv)
    if not (args.data / PUBLISHED).is_file():
        parser.error(f"{args.data / PUBLISHED} not found (--data names the staubli_tx40 folder)")
    c = compare(args.recording, args.data, values=args.values)
    print(json.dumps({**asdict(c), "sane": sane(c)}, indent=1) if args.json else markdown(c))
    return 0 if sane(c) else 1


if __name__ == "__main__":
    sys.exit(main())
