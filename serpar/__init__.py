"""serpar command line (``serpar`` / ``python -m serpar``); the physics lives in sim/ and friends."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")  # headless machines: offscreen rendering by EGL
if os.environ["MUJOCO_GL"] == "egl":
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
