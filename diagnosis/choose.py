"""Which family diagnoses a recording: chosen from what the recording holds."""

from __future__ import annotations

from pathlib import Path

from serpar.calibration.arm_static_data import panda_folder_data, static_data, to_recording
from serpar.calibration.panda_data import SOCKET_FILES, load_panda_folder
from serpar.diagnosis.arm_dynamics_family import ArmDynamicsConfig
from serpar.diagnosis.arm_dynamics_family import family_from_recording as dynamics_family
from serpar.diagnosis.arm_static_family import family_from_data
from serpar.diagnosis.episode_family import family_from_recording as episode_family
from serpar.diagnosis.episode_family import is_episode
from serpar.diagnosis.family import Family
from serpar.diagnosis.stewart_family import family_from_recording as stewart_family
from serpar.diagnosis.stewart_motion_effects import MOVING_SHARE, moving_share
from serpar.diagnosis.stewart_motion_family import family_from_recording as motion_family
from serpar.errors import ConfigError, IdentificationError
from serpar.kinematics.robot import PANDA, Robot
from serpar.sim.arm_from_file import arm_from_file
from serpar.sim.recording import Recording, read_recording
from serpar.sim.rigid_arm import PANDA_ARM

ARM_TORQUES = ("tau_J1", "tau_drive1")
"""A recording with q1 and either of these is an arm time series (the family names whatever
else of the arm's channels it lacks)."""
STEWART_PREFIXES = ("leg", "platform_")
"""A recording with any channel starting so is meant for the Stewart family, which then names
whichever of its channels are missing."""
WHAT = ("a measurements table (q1..q7 with x/y/z or socket: a static calibration set), or arm "
        "signals q1..7 and tau_J1..7 (a time series, or an assembly episode of serpar run "
        "--record), or Stewart signals leg_cmd1..6, leg1..6, "
        "platform_x/y/z/qw/qx/qy/qz (rest holds of the platform, or the platform moving "
        "continuously), or a panda_1-layout folder")
NOTES = "notes"
"""Key of ``meta.model`` listing, one line each, what the import of the data did not read."""


def is_panda_folder(path: Path) -> bool:
    """Any sub-folder with a socket file: one with only one of them is then refused by the
    loader naming the missing file, not as "not a recording"."""
    return (path.is_dir() and not (path / "meta.json").exists()
            and any((d / f).is_file() for d in path.iterdir() if d.is_dir()
                    for f in SOCKET_FILES))


def load_for_diagnosis(path: str | Path, robot: Robot = PANDA) -> Recording:
    """A recording folder, or a panda_1-layout folder of ``robot``'s angles converted to one."""
    src = Path(path)
    if not src.exists():
        raise IdentificationError(f"{src} does not exist; expected a recording folder "
                                  "(meta.json + tables) or a panda_1-layout folder")
    if is_panda_folder(src):
        raw = load_panda_folder(src, robot)
        return to_recording(panda_folder_data(raw), "real",
                            {"imported_from": f"panda_1 layout: {src}", NOTES: list(raw.notes)})
    return read_recording(src)


def load_notes(rec: Recording) -> list[str]:
    """What loading the recording skipped (files of a panda_1-layout folder that are not
    socket files), one line each, for the user to see; empty for a recording as written."""
    notes = rec.meta.model.get(NOTES, []) if isinstance(rec.meta.model, dict) else []
    return [str(n) for n in notes] if isinstance(notes, list) else []


def family_from_recording(rec: Recording, robot: Robot = PANDA,
                          dynamics: ArmDynamicsConfig | None = None) -> Family:
    """The static arm family when the recording has measurements, else the episode family
    for an assembly episode (``serpar run --record``), else the arm-dynamics family when it has
    the arm's joint signals, else a Stewart family when it has Stewart
    leg or platform channels (the motion family when the leg commands change at most samples,
    the rest-hold family otherwise); else one line saying what is needed. ``robot``: the arm
    of a static or arm-dynamics recording (episodes and the Stewart platform are the Panda
    cell's); ``dynamics``: the arm-dynamics family's settings (its split)."""
    if rec.measurements is not None and rec.measurements.num_rows > 0:

        return family_from_data(static_data(rec, robot))
    cols = set(rec.signals.column_names)
    arm_series = (rec.signals.num_rows > 0 and "q1" in cols
                  and any(c in cols for c in ARM_TORQUES))
    if robot is not PANDA:
        if not arm_series or is_episode(rec):
            raise ConfigError(f"--robot {robot.source}: the static (point/position) and the "
                              "arm-dynamics diagnosis take another robot; this recording is "
                              "neither (episodes and the Stewart platform are the Panda cell's)")
        return dynamics_family(rec, dynamics, arm_from_file(robot.source))
    if dynamics is not None and (not arm_series or is_episode(rec)):
        raise ConfigError("--train/--heldout split an arm-dynamics time series; this recording "
                          "is not one")
    if arm_series:

        if is_episode(rec):
            # --- an assembly episode: arm dynamics over its free-motion phases (episode.py)

            return episode_family(rec)
        # --- arm dynamics time series (diagnosis/arm_dynamics_family.py, a sibling domain)

        return dynamics_family(rec, dynamics, PANDA_ARM)
    if rec.signals.num_rows > 0 and any(c.startswith(STEWART_PREFIXES) for c in cols):

        if moving_share(rec) > MOVING_SHARE:
            # --- Stewart platform in continuous motion (diagnosis/stewart_motion_family.py)

            return motion_family(rec)
        # --- Stewart platform rest holds (diagnosis/stewart_family.py)

        return stewart_family(rec)
    raise IdentificationError(f"the recording holds nothing diagnosable; needs {WHAT} "
                              f"(it has: {', '.join(sorted(cols)) or 'no channels'}, "
                              f"{rec.signals.num_rows} samples, "
                              f"{'no' if rec.measurements is None else rec.measurements.num_rows} "
                              "measurement rows)")
