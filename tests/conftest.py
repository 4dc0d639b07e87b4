# MuJoCo picks its GL backend when first imported and tests import mujoco directly:
# importing serpar first applies the package's headless default (MUJOCO_GL=egl when unset).
import pytest

import serpar  # noqa: F401


@pytest.fixture(scope="session")
def calibrated_top():
    """The top pair calibrated from noisy full-size board frames (~50 s; tests that use it share
    the xdist group 'calibrated' so one worker pays for it)."""
    from serpar.calibration.camera_calibration import calibrate
    from serpar.vision.imaging import ImagingConfig

    return calibrate("top", ImagingConfig(), seed=0)


@pytest.fixture(scope="session")
def calibrated_inspect():
    """The in-hand pair calibrated from noisy full-size board frames (~15 s)."""
    from serpar.calibration.camera_calibration import calibrate
    from serpar.vision.imaging import ImagingConfig

    return calibrate("inspect", ImagingConfig(), seed=0)
