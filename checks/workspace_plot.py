"""Point-cloud figure of the Stewart workspace, laid out like seed 000 Fig. 6."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from serpar.errors import ConfigError

MAX_3D_POINTS = 40_000
"""3-D scatter is subsampled to this (seeded) so the figure renders in about a second."""


SEED_BOX_MM = ((-100.0, 100.0), (-100.0, 100.0), (230.0, 300.0))


def plot_workspace(points_valid: np.ndarray, out_png: str | Path, samples: int | None = None,
                   title: str | None = None,
                   limits_mm: tuple[tuple[float, float], ...] = SEED_BOX_MM) -> Path:
    """2x2 figure: (a) 3-D cloud, (b) Y-Z, (c) X-Z, (d) X-Y projections, axes in mm.

    points_valid: (k, 3) platform-frame origins [m] in the base frame. The axes span the
    sampling box (limits_mm, X, Y, Z), so the empty part of the box shows. Returns the path.
    """
    pts = np.asarray(points_valid, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ConfigError(f"points must be (k, 3), got {pts.shape}")
    out = Path(out_png)
    if out.suffix.lower() != ".png":
        raise ConfigError(f"plot path {str(out)!r}: must end in .png")
    if not out.parent.is_dir():
        raise ConfigError(f"plot path {str(out)!r}: folder {str(out.parent)!r} does not exist")
    import matplotlib

    matplotlib.use("Agg")  # headless: no display on the cluster or in tests
    import matplotlib.pyplot as plt

    mm = pts * 1e3
    count = f"{len(pts)} valid" + (f" of {samples}" if samples else "") + " poses"
    fig = plt.figure(figsize=(10, 9))
    fig.suptitle(title or f"Stewart platform workspace: {count}")
    ax3 = fig.add_subplot(2, 2, 1, projection="3d")
    sub = mm
    if len(mm) > MAX_3D_POINTS:
        sub = mm[np.random.default_rng(0).choice(len(mm), MAX_3D_POINTS, replace=False)]
    ax3.scatter(sub[:, 0], sub[:, 1], sub[:, 2], s=0.3, c="red", rasterized=True)
    ax3.set(xlabel="X [mm]", ylabel="Y [mm]", zlabel="Z [mm]", title="(a) 3-D",
            xlim=limits_mm[0], ylim=limits_mm[1], zlim=limits_mm[2])
    for k, (i, j, name) in enumerate(((1, 2, "(b) Y-Z"), (0, 2, "(c) X-Z"), (0, 1, "(d) X-Y"))):
        ax = fig.add_subplot(2, 2, k + 2)
        ax.scatter(mm[:, i], mm[:, j], s=0.2, c="red", rasterized=True)
        ax.set(xlabel=f"{'XYZ'[i]} [mm]", ylabel=f"{'XYZ'[j]} [mm]", title=name,
               xlim=limits_mm[i], ylim=limits_mm[j])
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
