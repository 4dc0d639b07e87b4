"""Which family diagnoses a recording: chosen from what the recording holds."""

from __future__ import annotations

from pathlib import Path

from identify.diagnosis.family import Family
from identify.errors import IdentificationError
from sim.recording import Recording, read_recording

DYNAMICS_CHANNELS = tuple(f"q{j}" for j in range(1, 8)) + tuple(f"tau_J{j}" for j in range(1, 8))
STEWART_PREFIXES = ("leg", "platform_")
"""A recording with any channel starting so is meant for the Stewart family, which then names
whichever of its channels are missing."""
WHAT = ("a measurements table (q1..q7 with x/y/z or socket: a static calibration set), or arm "
        "signals q1..7 and tau_J1..7 (a time series, or an assembly episode of serpar run "
        "--record), or Stewart signals leg_cmd1..6, leg1..6, "
        "platform_x/y/z/qw/qx/qy/qz (rest holds of the platform, or the platform moving "
        "continuously), or a panda_1-layout folder")


def is_panda_folder(path: Path) -> bool:
    return (path.is_dir() and not (path / "meta.json").exists()
            and any((d / "hole_0.csv").is_file() for d in path.iterdir() if d.is_dir()))


def load_for_diagnosis(path: str | Path) -> Recording:
    """A recording folder, or a panda_1-layout folder converted to one."""
    src = Path(path)
    if not src.exists():
        raise IdentificationError(f"{src} does not exist; expected a recording folder "
                                  "(meta.json + tables) or a panda_1-layout folder")
    if is_panda_folder(src):
        from identify.diagnosis.arm_static_data import panda_folder_data, to_recording

        return to_recording(panda_folder_data(str(src)), "real",
                            {"imported_from": f"panda_1 layout: {src}"})
    return read_recording(src)


def family_from_recording(rec: Recording) -> Family:
    """The static arm family when the recording has measurements, else the episode family
    for an assembly episode (``serpar run --record``), else the arm-dynamics family when it has
    the arm's joint signals, else a Stewart family when it has Stewart
    leg or platform channels (the motion family when the leg commands change at most samples,
    the rest-hold family otherwise); else one line saying what is needed."""
    if rec.measurements is not None and rec.measurements.num_rows > 0:
        from identify.diagnosis.arm_static import family_from_data
        from identify.diagnosis.arm_static_data import static_data

        return family_from_data(static_data(rec))
    cols = set(rec.signals.column_names)
    if rec.signals.num_rows > 0 and set(DYNAMICS_CHANNELS) <= cols:
        from identify.diagnosis.episode import is_episode

        if is_episode(rec):
            # --- an assembly episode: arm dynamics over its free-motion phases (episode.py)
            from identify.diagnosis.episode import family_from_recording as episode_family

            return episode_family(rec)
        # --- arm dynamics time series (identify/diagnosis/arm_dynamics.py, a sibling domain)
        from identify.diagnosis.arm_dynamics import family_from_recording as dynamics_family

        return dynamics_family(rec)
    if rec.signals.num_rows > 0 and any(c.startswith(STEWART_PREFIXES) for c in cols):
        from identify.diagnosis.stewart_motion_effects import MOVING_SHARE, moving_share

        if moving_share(rec) > MOVING_SHARE:
            # --- Stewart platform in continuous motion (identify/diagnosis/stewart_motion.py)
            from identify.diagnosis.stewart_motion import family_from_recording as motion_family

            return motion_family(rec)
        # --- Stewart platform rest holds (identify/diagnosis/stewart.py)
        from identify.diagnosis.stewart import family_from_recording as stewart_family

        return stewart_family(rec)
    raise IdentificationError(f"the recording holds nothing diagnosable; needs {WHAT} "
                              f"(it has: {', '.join(sorted(cols)) or 'no channels'}, "
                              f"{rec.signals.num_rows} samples, "
                              f"{'no' if rec.measurements is None else rec.measurements.num_rows} "
                              "measurement rows)")
