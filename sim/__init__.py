"""serpar simulation core: scene assembly, physics settings, rendering and validation.

Offscreen rendering must work without a display, so EGL is the default GL
backend unless the user chose one; this runs before mujoco is imported.
"""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
if os.environ["MUJOCO_GL"] == "egl":
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
