"""serpar: a MuJoCo simulator of a serial-parallel precision assembly cell.

The repository's top-level folders are this package's subpackages (pyproject.toml maps the
repository root to ``serpar``), layered bottom-up; each imports only from layers below it,
which ``lint-imports`` enforces (docs/layout.md):

    errors -> assets -> kinematics -> sim -> vision -> controllers -> calibration -> tasks
    -> diagnosis | twins -> checks -> cli

Offscreen rendering must work without a display, so EGL is the default GL backend unless the
user chose one; this runs before any serpar module imports mujoco.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
if os.environ["MUJOCO_GL"] == "egl":
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

__version__ = "0.1.0"
