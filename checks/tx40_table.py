"""The Stäubli TX40 diagnosed as a user would (``serpar diagnose REC --robot URDF --train
0.1:6 --heldout 6:7.5``), beside the authors' published identification (checks/tx40_published.py):
the friction, rotor inertia, coupled-motor and offset values of the model the diagnosis
selected, each beside the published OLS value, the parameters it cannot identify, and the
held-out RMS per joint in N m: CAD (offsets fitted) -> selected model, and the published
model on the same windows.

``python -m serpar.checks.tx40_table REC [--json]`` (REC: the recording of
docs/examples/tx40_import.yaml's import command).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from serpar.checks.tx40_published import (
    DATA,
    PUBLISHED,
    URDF,
    published_model,
    published_torque,
    read_published,
)
from serpar.diagnosis.arm_dynamics_family import ArmDynamicsConfig, family_from_recording
from serpar.diagnosis.arm_dynamics_grouping import link_regressor_at
from serpar.diagnosis.fit import fit_model
from serpar.diagnosis.select import diagnose
from serpar.sim.arm_from_file import arm_from_file
from serpar.sim.recording import read_recording

Vec = NDArray[np.float64]
TRAIN = (0.1, 6.0)
HELDOUT = (6.0, 7.5)


def _rms(x: Vec) -> list[float]:
    return [float(v) for v in np.sqrt(np.mean(x**2, axis=0))]


def tx40_table(recording: str | Path, data: Path = DATA) -> dict[str, object]:
    """Every figure of the docs' TX40 table (module docstring)."""
    arm = arm_from_file(str(data / URDF))
    fam = family_from_recording(read_recording(recording),
                                ArmDynamicsConfig(train_span=TRAIN, heldout_span=HELDOUT), arm)
    diag = diagnose(fam, 0)
    train, held = fam.split(np.random.default_rng(0))
    path = tuple(f.effect for f in diag.findings)
    base = fit_model(fam, (), train, held)
    fit = fit_model(fam, path, train, held, base.params)
    pub = published_model(read_published(data / PUBLISHED))
    t = fam.terms
    y = link_regressor_at(fam._models.dyn, t.q[held], t.dq[held], t.ddq[held])
    measured = t.drive[held] + t.tau_full_model[held]
    published = measured - published_torque(pub, y, t.dq[held], t.ddq[held])
    values = {name: dict(zip(e.param_names, fit.params[name], strict=True))
              for e in fam.effects if (name := e.name) in fit.params}
    values["tare"] = dict(zip(fam.baseline.param_names, fit.params[fam.baseline.name],
                              strict=True))
    return {
        "verdict": diag.verdict, "notes": list(fam.notes),
        "findings": [{"effect": f.effect, "established": f.established,
                      "reasons": list(f.reasons)} for f in diag.findings],
        "selected": list(path), "values": {k: {p: float(v) for p, v in d.items()}
                                           for k, d in values.items()},
        "std": {name: [float(s) for s in fit.std[name]] for name in fit.std},
        "published": pub.drive,
        "held": [e.param_names[i] for e in fam.effects for i in e.fixed],
        "rms_nominal": _rms(fam.misfits(base.params, held)[1]),
        "rms_fitted": _rms(fam.misfits(fit.params, held)[1]),
        "rms_published": _rms(published),
        "heldout_rows": int(held.size), "wall_s": diag.wall_s,
    }


def markdown(t: dict[str, object]) -> str:
    v, p = t["values"], t["published"]  # type: ignore[index]
    fr, out = v.get("joint_friction", {}), []  # type: ignore[union-attr]
    out.append("| joint | Fv fitted | fv published | Fc fitted | fs published | Ia fitted | "
               "Ia published | offset fitted | off published |")
    out.append("|---|---|---|---|---|---|---|---|---|")
    arm = v.get("armature", {})  # type: ignore[union-attr]
    for j in range(1, 7):
        fv, fc = fr.get(f"Fv{j}", float("nan")), fr.get(f"Fc{j}", float("nan"))
        ia = arm.get(f"Ia{j}")
        out.append(f"| {j} | {fv:.3f} | {p[f'fv{j}']:.3f} ({100 * (fv / p[f'fv{j}'] - 1):+.0f} %) "
                   f"| {fc:.3f} | {p[f'fs{j}']:.3f} ({100 * (fc / p[f'fs{j}'] - 1):+.0f} %) | "
                   f"{'held' if f'Ia{j}' in t['held'] else f'{ia:.4f}' if ia is not None else '-'}"  # type: ignore[operator]
                   f" | {p.get(f'Ia{j}', float('nan')):.4f} | {v['tare'][f'drive_tare{j}']:.3f} | "
                   f"{p[f'off{j}']:.3f} |")
    cp = v.get("coupled_pair", {})  # type: ignore[union-attr]
    out.append("")
    out.append("| coupled motor 6 | fitted | published |\n|---|---|---|")
    for name in ("Iam6", "fvm6", "fsm6"):
        out.append(f"| {name} | {cp.get(name, float('nan')):.4f} | {p[name]:.4f} |")
    out.append("")
    out.append("| joint | held-out RMS CAD [N m] | selected model | published model |")
    out.append("|---|---|---|---|")
    for j in range(6):
        out.append(f"| {j + 1} | {t['rms_nominal'][j]:.3f} | {t['rms_fitted'][j]:.3f} | "  # type: ignore[index]
                   f"{t['rms_published'][j]:.3f} |")  # type: ignore[index]
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording")
    ap.add_argument("--data", type=Path, default=DATA,
                    help=f"the staubli_tx40 folder (default {DATA})")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if not (args.data / URDF).is_file():
        ap.error(f"{args.data / URDF} not found (--data names the staubli_tx40 folder)")
    t = tx40_table(args.recording, args.data)
    print(json.dumps(t, indent=1) if args.json else markdown(t))
    return 0


if __name__ == "__main__":
    sys.exit(main())
