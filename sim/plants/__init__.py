"""The simulated "real" machines that the twins, the calibration campaigns, the episodes and the
diagnosis share: changes MuJoCo expresses exactly (friction, damping, armature, payload, delays),
backlash, the static and moving Pandas of the campaigns and twins, and the Stewart platform."""
