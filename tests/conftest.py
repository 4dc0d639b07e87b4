import os

# MuJoCo picks its GL backend when it is first imported; tests import mujoco directly,
# so set the headless default here as sim/__init__.py does for package users.
os.environ.setdefault("MUJOCO_GL", "egl")
if os.environ["MUJOCO_GL"] == "egl":
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
