# MuJoCo picks its GL backend when first imported and tests import mujoco directly:
# importing sim first applies the package's headless default (MUJOCO_GL=egl when unset).
import sim  # noqa: F401
