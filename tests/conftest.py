# MuJoCo picks its GL backend when first imported and tests import mujoco directly:
# importing serpar first applies the package's headless default (MUJOCO_GL=egl when unset).
import os

import pytest
from hypothesis import settings

import serpar  # noqa: F401

# The fuzz tests draw the same examples on every run (CI must not go red by chance); set
# HYPOTHESIS_PROFILE=explore to draw fresh ones.
settings.register_profile("ci", derandomize=True, database=None, deadline=None)
settings.register_profile("explore", deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


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


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Under ``--dist loadgroup`` a module's tests that share a module-scoped fixture of their
    own module (a recorded twin, a sim2real run) go to one worker: split over two, each worker
    would build the fixture again (minutes for the episode fixtures). A test already in a
    group keeps it; before xdist's own hook, which reads the marker."""
    for item in items:
        if item.get_closest_marker("xdist_group") is not None:
            continue
        module = item.nodeid.split("::", 1)[0]
        defs = getattr(item, "_fixtureinfo", None)
        if defs is None:
            continue
        if any(fd[-1].scope in ("module", "package") and fd[-1].baseid == module
               for fd in defs.name2fixturedefs.values()):
            item.add_marker(pytest.mark.xdist_group(module.rsplit("/", 1)[-1]))
