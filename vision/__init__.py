"""Vision for the six-step sequence: stereo calibration and registration to the arm base,
conductor localisation in the tray, hole finding on the baseplate, in-hand inspection.

Everything here works on images (rendered now, real later) and on the calibrated
camera models; simulator ground truth is used only by the scoring in ``checks/``.
"""

if not __name__.startswith("serpar."):  # a repository folder is a serpar subpackage, not a top-level name
    raise ModuleNotFoundError(f"No module named {__name__!r}; import serpar.{__name__}", name=__name__)
