"""The Stewart campaign measured by the top stereo pair instead of motion capture (issue 6's
second pose source): at each settled pose the pair that sees the baseplate takes one shot,
:func:`serpar.vision.plate.locate_holes` fits the plate pose to the pixels, and the fixture
(``platform_T_plate``, a design constant) turns it into the platform pose.

**The frame, and the gauge.** The cameras measure in the arm base frame; the identification
needs the platform in the Stewart base frame, and the camera -> Stewart-base transform is not
known to a real cell. It is taken the way :meth:`PlateCommander.register` takes it in every
episode: one plate measurement with the platform settled at its start (home) pose, read
through the model in use. With the nominal model that registered frame is off the true base
by the platform's home-pose error E (hidden errors: up to ~1 mm and 0.5 deg). Identifying E
with the 42 parameters instead would not help: poses measured in a frame moved by any rigid E
are explained *exactly* by base joints E^-1 (B_i + dB_i), so the six registration parameters
and the dB are not separately identifiable (rank 42 of 48) and some gauge must be fixed. The
home registration fixes it; the identified dB absorb E, and the model is right in the
registered frame, which is where the cell uses it: the episode registers again at home with
the identified model and gets that same frame back. So every stereo campaign registers at its
start with the model it drives, and its poses are scored against the simulator's truth
expressed in that registered frame (the truth of the base's place enters the scoring only).

Poses the pair cannot measure are skipped and reported, never dropped silently: the plate (its
outer top edge plus a margin) must lie inside both images where the model and the
registration predict it, the detector must find the plate (a typed VisionError otherwise), and
the fitted pose must be within half a hole pitch of the prediction (a grid assigned one hole
off would be a full pitch away).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from serpar.calibration.camera_cache import calibrated_pair
from serpar.calibration.stewart_campaign import (
    CampaignCell,
    CampaignResult,
    SettleCriterion,
    random_poses,
)
from serpar.calibration.stewart_identification import StewartMeasurements
from serpar.controllers.plate_commander import inverse, platform_T_plate, transform
from serpar.controllers.stewart_servo import platform_pose
from serpar.errors import ConfigError, IdentificationError, LimitError
from serpar.kinematics.stewart_kinematics import StewartGeometry
from serpar.sim import names
from serpar.sim.baseplate import BaseplateConfig
from serpar.sim.scene import SceneConfig, build_scene
from serpar.vision.camera import StereoPair
from serpar.vision.errors import VisionError
from serpar.vision.imaging import Camera, ImagingConfig
from serpar.vision.layout import PlateLayout, plate_layout
from serpar.vision.plate import PlateMeasurement, locate_holes

TOP = ("top_left", "top_right")
WIDTHS = (2048, 1024, 512)
"""Readout widths the plate detector is tuned for (``serpar vision-check``'s)."""
NOMINAL = SceneConfig()
"""The cell as designed: what the vision assumes."""
STEREO_HOLD = SettleCriterion.fixed(0.4)
"""A fixed 0.4 s at each pose, not motion capture's settle: the pair measures a plate pose to
20-70 um, and the legs' last 1-3 um of settling buy it nothing. (Its measurement moves by
6-68 um when the true pose moves by 0.4-4 um, so a 10-pose result at 1024 px is a fresh
noise draw for any change of hold: 0.16-0.39 mm of verification RMS over six holds tried.)"""


@dataclass(frozen=True)
class StereoConfig:
    """How the top pair measures the campaign's poses."""

    width: int = 2048
    """Readout width [px]; the cached full-size calibration is scaled to it (as in an episode)."""
    noise: bool = True
    """Sensor noise and lighting variation on, as in the episode."""
    margin_px: float = 16.0
    """The plate's outer edge must be this far inside both images [px at full size]: the edge
    fit samples it, and a hole row cut by the image border would bias the fit."""
    max_offset_m: float = 5e-3
    """Largest accepted distance of the fitted plate from where the model predicts it: half the
    10 mm hole pitch (a grid assigned one hole off lands a whole pitch away)."""
    calibration_seed: int = 0

    def __post_init__(self) -> None:
        if self.width not in WIDTHS:
            raise ConfigError(f"stereo width {self.width}; valid: {', '.join(map(str, WIDTHS))}")
        if not 0 <= self.margin_px <= 200 or not 0 < self.max_offset_m <= 0.01:
            raise ConfigError(f"stereo margin {self.margin_px} px (valid 0..200), max offset "
                              f"{self.max_offset_m} m (valid 0..0.01)")

    @property
    def imaging(self) -> ImagingConfig:
        return ImagingConfig(width=self.width) if self.noise else ImagingConfig.ideal(self.width)


def top_pair(cfg: StereoConfig) -> StereoPair:
    pair = calibrated_pair("top", 2048, seed=cfg.calibration_seed)
    return pair.scaled(cfg.imaging.size)


def plate_outline(plate: BaseplateConfig = NOMINAL.baseplate) -> np.ndarray:
    """(4, 3) corners of the plate's top face in the plate frame [m]."""
    hx = plate.cols * plate.pitch / 2 + plate.margin
    hy = plate.rows * plate.pitch / 2 + plate.margin
    return np.array([[sx * hx, sy * hy, plate.thickness] for sx in (-1, 1) for sy in (-1, 1)])


def view_problem(pair: StereoPair, base_T_plate: np.ndarray, margin_px: float) -> str:
    """'' if the plate's top face lies inside both images with the margin, else why not."""
    corners = plate_outline() @ base_T_plate[:3, :3].T + base_T_plate[:3, 3]
    out = []
    for cam in (pair.left, pair.right):
        m = margin_px * cam.size[0] / 2048
        uv = cam.project(corners)
        past = max(float(np.max(m - uv)), float(np.max(uv - (np.asarray(cam.size) - m))))
        if past > 0:
            out.append(f"plate {past:.0f} px past the margin of {cam.name}")
    return "; ".join(out)


def in_view(pair: StereoPair, stewart_base: np.ndarray, platform_T_plate: np.ndarray,
            pos: np.ndarray, rot: np.ndarray, margin_px: float) -> list[str]:
    """Per pose, '' or why the plate would be out of view, the Stewart base at `stewart_base`
    (4x4 in the arm base frame): for planning from the cell drawing."""
    return [view_problem(pair, stewart_base @ transform(r, p) @ platform_T_plate, margin_px)
            for p, r in zip(pos, rot)]


def _shoot(camera: Camera, cell: CampaignCell, pair: StereoPair, layout: PlateLayout) -> PlateMeasurement:
    frames = camera.shoot(cell.scene.data, TOP)
    return locate_holes(pair, frames[TOP[0]], frames[TOP[1]], NOMINAL.baseplate, NOMINAL.conductor, layout)


def _layout_at(base_T_plate: np.ndarray) -> PlateLayout:
    """The detector's prior: the plate where the model and registration predict it."""
    return PlateLayout(tuple(base_T_plate[:3, 3]), tuple(map(tuple, base_T_plate[:3, :3])))


def stereo_campaign(scene_cfg: SceneConfig, pos: np.ndarray, rot: np.ndarray, believed: np.ndarray | None,
                    cfg: StereoConfig, pair: StereoPair | None, seed: int = 0, measure: bool = True) -> CampaignResult:
    """Drive the platform (hidden errors in `scene_cfg`) through the poses with the model with
    `believed` errors, register at home and measure each settled pose with the top pair
    (`measure` False: the truth only, for scoring; no shot is taken, `pair` may be None). A pose
    the model cannot reach within the strokes is skipped, reported, its truth NaN.

    The truth is returned in the frame an error-free camera would register, X_h P_h^-1 P_k (X_h:
    the home pose the model reads at the start strokes, P_h, P_k: the true poses): the frame the
    model is used in. A camera error common to the home shot and a pose cancels in the
    registered measurement as it does in the cell, so what is left of the measurement error is
    what the identification sees."""
    cell = CampaignCell.create(scene_cfg, believed, seed, STEREO_HOLD)
    cell.hold()  # the legs settle on the start strokes before the registration shot
    model, data = cell.scene.model, cell.scene.data
    home = transform(*platform_pose(model, data, names.STEWART)[::-1])
    frame = cell.plate.commanded @ inverse(home)  # true Stewart base -> the ideally registered frame
    camera = Camera(model, cfg.imaging, seed=seed + 104729) if measure else None
    strokes, truth, kept, skipped, measured = [], [], [], [], []
    registration_error = None
    try:
        if camera is not None:
            if pair is None:
                raise ConfigError("a stereo campaign that measures needs the calibrated top pair")
            try:
                cell.plate.register(_shoot(camera, cell, pair, plate_layout(NOMINAL)))
            except VisionError as exc:
                raise ConfigError(f"stereo registration at home failed: {type(exc).__name__}: {exc}") from None
            world_T_base = _world_T_base(cell)  # scoring only: the registration's own error
            reg_err = inverse(world_T_base @ inverse(frame)) @ cell.plate.base_T_stewart
            registration_error = (float(np.linalg.norm(reg_err[:3, 3])),
                                  float(np.linalg.norm(Rotation.from_matrix(reg_err[:3, :3]).as_rotvec())))
        for k, (p, r) in enumerate(zip(pos, rot)):
            try:
                s, tp, tr = cell.settle_at(p, r)
            except LimitError as exc:  # a poorly identified model can ask for strokes past an end
                skipped.append((k, f"the model in use cannot reach it: {exc}"))
                truth.append(np.full((4, 4), np.nan))
                continue
            truth.append(frame @ transform(tr, tp))
            if camera is None:
                continue
            predicted = cell.plate.plate_pose()
            why = view_problem(pair, predicted, cfg.margin_px)
            if not why:
                try:
                    plate = _shoot(camera, cell, pair, _layout_at(predicted))
                    found = transform(plate.rotation, plate.origin)
                    off = float(np.linalg.norm(found[:3, 3] - predicted[:3, 3]))
                    if off > cfg.max_offset_m:
                        why = f"fitted plate {off * 1e3:.1f} mm from the predicted (grid misassigned?)"
                except VisionError as exc:
                    why = f"{type(exc).__name__}: {exc}"
            if why:
                skipped.append((k, why))
                continue
            strokes.append(s)
            kept.append(k)
            measured.append(inverse(cell.plate.base_T_stewart) @ found @ inverse(cell.plate.platform_T_plate))
    finally:
        if camera is not None:
            camera.close()
    truth_a = np.array(truth)
    meas = None
    if camera is not None:
        m = np.array(measured).reshape(-1, 4, 4)
        try:
            meas = StewartMeasurements(np.array(strokes).reshape(-1, 6), m[:, :3, 3], m[:, :3, :3])
        except IdentificationError as exc:  # too few poses left: name the skipped ones
            raise ConfigError(f"stereo campaign: {exc}; skipped: " + "; ".join(
                f"pose {k + 1}: {why}" for k, why in skipped)) from None
    return CampaignResult(meas, truth_a[:, :3, 3], truth_a[:, :3, :3], np.array(kept, int), tuple(skipped),
                          registration_error)


def _world_T_base(cell: CampaignCell) -> np.ndarray:
    body = cell.scene.model.body(names.STEWART + "base").id
    return transform(cell.scene.data.xmat[body].reshape(3, 3), cell.scene.data.xpos[body])


def visible_random_poses(n: int, seed: int, geometry: StewartGeometry, visible: Callable[[np.ndarray, np.ndarray],
                         list[str]]) -> tuple[np.ndarray, np.ndarray]:
    """`n` random poses (as :func:`random_poses`) that `visible` finds in view."""
    pos, rot = np.zeros((0, 3)), np.zeros((0, 3, 3))
    for k in range(50):
        p, r = random_poses(max(n, 20), seed + 1000 * k, geometry)
        ok = np.array([not why for why in visible(p, r)])
        pos, rot = np.r_[pos, p[ok]], np.r_[rot, r[ok]]
        if len(pos) >= n:
            return pos[:n], rot[:n]
    raise ConfigError(f"fewer than {n} random poses keep the plate in the top cameras' view")


def planning_view(cfg: StereoConfig, scene_cfg: SceneConfig) -> Callable[[np.ndarray, np.ndarray], list[str]]:
    """Which poses the pair will see, from the cell drawing (the Stewart base where the layout
    puts it) and the nominal kinematics: for choosing training poses before the campaign."""

    pair = top_pair(cfg)
    fixture = platform_T_plate(build_scene(dataclasses.replace(NOMINAL, n_conductors=0)).model)
    base = transform(np.eye(3), np.asarray(scene_cfg.stewart_base, float))
    return lambda pos, rot: in_view(pair, base, fixture, pos, rot, cfg.margin_px)


def regauge(errors: np.ndarray, geometry: StewartGeometry) -> np.ndarray:
    """The same platform in the base frame where its base joints sit, as a rigid set, where the
    design puts them: the rigid transform G best aligning B_i + dB_i onto B_i (Kabsch) is
    applied to the base joints, dB'_i = G (B_i + dB_i) - B_i; dl and dP are frame-free.

    Why: stereo poses live in the frame registered at home through the nominal model, off the
    true base by the platform's home error E, and the identified dB absorb E exactly (the gauge
    above). Left there, the model commands every pose E away from where the nominal plan put
    it, enough (~1.5 mm of stroke at 0.5 deg) to push poses planned near a stroke end out of
    range. Any frame is as right as any other once the cell registers the model at home, so the
    one closest to the design is chosen: it leaves only the rigid part of the true dB, which no
    pose measurement relative to an unknown base can see."""
    e = np.array(errors, float).reshape(6, 7)
    nominal = np.asarray(geometry.base_joints, float)
    built = nominal + e[:, 4:7]
    cb, cn = built.mean(axis=0), nominal.mean(axis=0)
    u, _, vt = np.linalg.svd((built - cb).T @ (nominal - cn))
    rot = vt.T @ np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))]) @ u.T
    e[:, 4:7] = (built - cb) @ rot.T + cn - nominal
    return e
