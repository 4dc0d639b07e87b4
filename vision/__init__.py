"""Vision for the six-step sequence: stereo calibration and registration to the arm base,
conductor localisation in the tray, hole finding on the baseplate, in-hand inspection.

Everything here works on images (rendered now, real later) and on the calibrated
camera models; simulator ground truth is used only by the scoring in ``tasks/``.
"""
