"""Per-pose platform errors before and after calibration, like seed 000 Figs. 8-9 / 11-12."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from serpar.calibration.stewart_calibration import PoseErrors, StewartCalibrationReport


def _panel(axes, errs: PoseErrors, title: str) -> None:
    k = np.arange(1, len(errs.position) + 1)
    for i, name in enumerate("xyz"):
        axes[0].plot(k, errs.position[:, i] * 1e3, "o-", label=name)
        axes[1].plot(k, np.degrees(errs.rotation[:, i]), "o-", label=f"about {name}")
    axes[0].set(title=f"{title}: position", xlabel="pose", ylabel="error [mm]")
    axes[1].set(title=f"{title}: rotation", xlabel="pose", ylabel="error [deg]")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)


def plot_report(report: StewartCalibrationReport, folder: str | Path) -> list[Path]:
    """One PNG for the errors before calibration and one per solver after; returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    panels = [("before", report.before_train)] + [(f"after_{o.solver}", o.train) for o in report.outcomes
                                                  if o.failure is None]
    paths = []
    for name, errs in panels:
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), constrained_layout=True)
        _panel(axes, errs, name.replace("_", " "))
        paths.append(out / f"stewart_{name}.png")
        fig.savefig(paths[-1], dpi=110)
        plt.close(fig)
    return paths
