"""The cell in a rerun file: the model's geoms once, body poses over time, camera frames,
time series and annotations, on one duration timeline ("sim_time").

Writes to a file sink only (never starts a viewer). Geoms are logged static in their body's
frame under ``cell/<body>`` and the bodies move by their world poses, so the viewer composes
them; bodies welded to the world get one static pose.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from pathlib import Path

import mujoco
import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from serpar.sim import channels as ch

APP_ID = "serpar"
"""The rerun application id of every serpar recording (a blueprint applies to one id)."""
TIMELINE = "sim_time"
ROOT = "cell"
IMAGE_WIDTH = 512
"""Camera frames are block-averaged down to at most this width (and JPEG-compressed)."""
PINHOLE, IMAGE = "pinhole", "image"
"""A camera's entity holds its pose, the child PINHOLE its intrinsics, PINHOLE/IMAGE its frames."""
EYE, LOOK_AT = (1.19, 0.706, 0.727), (0.42, 0.06, 0.28)
"""The 3-D view's first eye: the direction of `serpar render`'s overview camera (sim/render.py:
azimuth -140 deg, elevation -24 deg), 1.1 m from its look-at point instead of 1.55 m."""
_G = mujoco.mjtGeom
_SUFFIX = re.compile(r"(\d+|_(x|y|z|qw|qx|qy|qz))$")


def xyzw(wxyz: np.ndarray) -> np.ndarray:
    """MuJoCo quaternions are (w, x, y, z); rerun's are (x, y, z, w)."""
    return np.roll(np.asarray(wxyz, dtype=float), -1, axis=-1)


def body_path(model: mujoco.MjModel, body: int) -> str:
    return f"{ROOT}/{model.body(body).name or f'body{body}'}"


def open_stream(path: Path, name: str) -> rr.RecordingStream:
    """A stream into `path` only. Its id is random (the viewer merges recordings that share
    one); `name` is what the viewer lists."""
    rec = rr.RecordingStream(APP_ID)
    rec.save(path)
    rec.send_recording_name(name)
    return rec


def _rotations(quats: np.ndarray) -> np.ndarray:
    out = np.empty((len(quats), 9))
    for k, q in enumerate(quats):
        mujoco.mju_quat2Mat(out[k], q)
    return out.reshape(-1, 3, 3)


def _mesh(model: mujoco.MjModel, geoms: np.ndarray, rgba: np.ndarray) -> rr.Mesh3D:
    """The body's mesh geoms merged into one mesh in the body frame."""
    verts, faces, colors, base = [], [], [], 0
    for g, rot in zip(geoms, _rotations(model.geom_quat[geoms])):
        m = model.geom_dataid[g]
        v0, nv = model.mesh_vertadr[m], model.mesh_vertnum[m]
        f0, nf = model.mesh_faceadr[m], model.mesh_facenum[m]
        verts.append(model.mesh_vert[v0:v0 + nv] @ rot.T + model.geom_pos[g])
        faces.append(model.mesh_face[f0:f0 + nf] + base)
        colors.append(np.repeat(rgba[g][None], nv, axis=0))
        base += nv
    return rr.Mesh3D(vertex_positions=np.concatenate(verts), triangle_indices=np.concatenate(faces),
                     vertex_colors=np.concatenate(colors))


def log_geometry(rec: rr.RecordingStream, model: mujoco.MjModel) -> None:
    """Every visible geom (group < 3, alpha > 0) as a rerun primitive, per body and type."""
    mat = model.geom_matid
    rgba = np.where((mat >= 0)[:, None], model.mat_rgba[np.maximum(mat, 0)], model.geom_rgba)
    rgba8 = (np.clip(rgba, 0, 1) * 255).astype(np.uint8)
    solid = rr.components.FillMode.Solid
    for b in range(model.nbody):
        a, n = model.body_geomadr[b], model.body_geomnum[b]
        ids = np.arange(a, a + n) if a >= 0 else np.zeros(0, int)
        ids = ids[(model.geom_group[ids] < 3) & (rgba[ids, 3] > 0)]
        base = body_path(model, b) + "/geoms"
        for kind in np.unique(model.geom_type[ids]):
            g = ids[model.geom_type[ids] == kind]
            size, pos, quat, col = model.geom_size[g], model.geom_pos[g], xyzw(model.geom_quat[g]), rgba8[g]
            if kind == _G.mjGEOM_BOX:
                item = rr.Boxes3D(half_sizes=size, centers=pos, quaternions=quat, colors=col, fill_mode=solid)
            elif kind in (_G.mjGEOM_SPHERE, _G.mjGEOM_ELLIPSOID):
                half = np.repeat(size[:, :1], 3, axis=1) if kind == _G.mjGEOM_SPHERE else size
                item = rr.Ellipsoids3D(half_sizes=half, centers=pos, quaternions=quat, colors=col, fill_mode=solid)
            elif kind == _G.mjGEOM_CYLINDER:
                item = rr.Cylinders3D(lengths=2 * size[:, 1], radii=size[:, 0], centers=pos, quaternions=quat,
                                      colors=col, fill_mode=solid)
            elif kind == _G.mjGEOM_CAPSULE:  # rerun's capsule runs from its origin along +z
                start = pos - _rotations(model.geom_quat[g])[:, :, 2] * size[:, 1:2]
                item = rr.Capsules3D(lengths=2 * size[:, 1], radii=size[:, 0], translations=start,
                                     quaternions=quat, colors=col)
            elif kind == _G.mjGEOM_MESH:
                item = _mesh(model, g, rgba8)
            elif kind == _G.mjGEOM_PLANE:  # infinite planes (size 0) drawn 2 m wide
                half = np.column_stack([np.where(size[:, :2] > 0, size[:, :2], 1.0), np.full(len(g), 1e-4)])
                item = rr.Boxes3D(half_sizes=half, centers=pos, quaternions=quat, colors=col, fill_mode=solid)
            else:  # heightfields, SDFs, flexes: not in the cell
                continue
            rec.log(f"{base}/{_G(kind).name.removeprefix('mjGEOM_').lower()}", item, static=True)


class PoseTrack:
    """World poses of the moving bodies, sampled by the caller's clock, sent as columns."""

    def __init__(self, rec: rr.RecordingStream, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        moving = (model.body_weldid != 0) | (model.body_mocapid >= 0)
        self.bodies = np.flatnonzero(moving)
        self.names = [model.body(b).name for b in self.bodies]
        self.paths = [body_path(model, b) for b in self.bodies]
        for b in np.flatnonzero(~moving):
            rec.log(body_path(model, b), rr.Transform3D(translation=data.xpos[b], quaternion=xyzw(data.xquat[b])),
                    static=True)
        self._t: list[float] = []
        self._pos: list[np.ndarray] = []
        self._quat: list[np.ndarray] = []

    def rebind(self, model: mujoco.MjModel) -> None:
        """Follow the same bodies in a recompiled model (their ids may have moved)."""
        self.bodies = np.array([model.body(name).id for name in self.names])

    def sample(self, data: mujoco.MjData, t: float) -> None:
        self.add(t, data.xpos, data.xquat)

    def add(self, t: float, xpos: np.ndarray, xquat: np.ndarray) -> None:
        """A sample from one simulation's body poses (nbody x 3, nbody x 4), e.g. a batch's row."""
        self._t.append(t)
        self._pos.append(xpos[self.bodies])
        self._quat.append(xquat[self.bodies])

    def send(self, rec: rr.RecordingStream) -> None:
        """Per body only the samples where it moved (resting and sleeping parts cost nothing)."""
        if not self._t:
            return
        t = np.asarray(self._t)
        pos, quat = np.stack(self._pos, axis=1), xyzw(np.stack(self._quat, axis=1))
        for k, path in enumerate(self.paths):
            keep = np.ones(len(t), bool)
            keep[1:] = np.any(pos[k, 1:] != pos[k, :-1], axis=1) | np.any(quat[k, 1:] != quat[k, :-1], axis=1)
            rec.send_columns(path, [rr.TimeColumn(TIMELINE, duration=t[keep])],
                             rr.Transform3D.columns(translation=pos[k, keep], quaternion=quat[k, keep]))


def downscale(image: np.ndarray, width: int = IMAGE_WIDTH) -> np.ndarray:
    """Block mean by the smallest integer factor that brings the width to <= `width`."""
    k = -(-image.shape[1] // width)
    if k <= 1:
        return image
    h, w = image.shape[0] // k * k, image.shape[1] // k * k
    blocks = image[:h, :w].reshape(h // k, k, w // k, k, -1).mean(axis=(1, 3))
    return np.rint(blocks).astype(np.uint8).reshape(h // k, w // k, *image.shape[2:])


def camera_path(name: str) -> str:
    """The camera's posed entity; its pinhole is the child ``PINHOLE`` and its frames below that."""
    return f"{ROOT}/cameras/{name}"


def log_frames(rec: rr.RecordingStream, model: mujoco.MjModel, data: mujoco.MjData,
               frames: dict[str, np.ndarray], t: float) -> None:
    """Each frame (downscaled, JPEG) under its camera, posed where the camera is now.

    Three entities per camera: the pose on ``cameras/<name>``, the pinhole on its child and the
    image below the pinhole. rerun 0.41 draws an image in a 2-D view only when it lies *below*
    a pinhole entity: logged on the pinhole's own entity (as before) the camera views were a
    grey box in the viewer, JPEG or raw alike. Its Pinhole docs also say a Transform3D on the
    pinhole's entity takes precedence over the Pinhole, so the pose stays one level up."""
    rec.set_time(TIMELINE, duration=t)
    for name, image in frames.items():
        cam = model.camera(name).id
        small = downscale(image)
        h, w = small.shape[:2]
        path = camera_path(name)
        rec.log(path, rr.Transform3D(translation=data.cam_xpos[cam], mat3x3=data.cam_xmat[cam].reshape(3, 3)))
        rec.log(f"{path}/{PINHOLE}", rr.Pinhole(fov_y=np.radians(model.cam_fovy[cam]), aspect_ratio=w / h,
                                                resolution=[w, h], camera_xyz=rr.ViewCoordinates.RUB,
                                                image_plane_distance=0.05))
        rec.log(f"{path}/{PINHOLE}/{IMAGE}", rr.Image(small).compress(jpeg_quality=85))


def signal_group(channel: str) -> str:
    """signals/<group>: q1..7 are one entity (one plot, a named series each); commanded and
    measured leg lengths share one."""
    group = _SUFFIX.sub("", channel)
    return f"signals/{'leg' if group == 'leg_cmd' else group}"


def send_signals(rec: rr.RecordingStream, time: np.ndarray, columns: dict[str, np.ndarray]) -> None:
    """The channels as scalar series, one entity per group (sharing its time column)."""
    groups: dict[str, list[str]] = {}
    for name in columns:
        groups.setdefault(signal_group(name), []).append(name)
    index = [rr.TimeColumn(TIMELINE, duration=time)]
    for path, chans in groups.items():
        rec.log(path, rr.SeriesLines(names=chans), static=True)
        rec.send_columns(path, index, rr.Scalars.columns(scalars=np.column_stack([columns[c] for c in chans])))


def log_text(rec: rr.RecordingStream, entity: str, text: str, t: float) -> None:
    rec.set_time(TIMELINE, duration=t)
    rec.log(entity, rr.TextLog(text, level=rr.TextLogLevel.INFO))


def blueprint(entity_paths: Iterable[str]) -> rrb.Blueprint:
    """The replay layout for a recording with these entities: the cell in 3-D beside one 2-D
    view per camera (named after it), the signal groups as tabs beside the phase and event log.

    `serpar replay` sends it with the file: the viewer's own heuristics title every camera view
    ".../pinhole/image" and show only some of the signal groups. The 3-D view leaves the frames
    out (the frustums stay): rerun 0.41's web viewer drew each one metres wide across the cell
    instead of on its frustum's image plane."""
    paths = [p.strip("/") for p in entity_paths]
    image = re.compile(rf"{ROOT}/cameras/([^/]+)/{PINHOLE}/{IMAGE}")
    cameras = sorted({m[1] for p in paths if (m := image.fullmatch(p))})
    frames = [f"/{camera_path(c)}/{PINHOLE}/{IMAGE}" for c in cameras]
    order = {signal_group(c): k for k, c in reversed(list(enumerate(ch.KNOWN)))}  # the schema's order
    signals = sorted({p for p in paths if p.startswith("signals/") and p.count("/") == 1},
                     key=lambda p: (order.get(p, len(order)), p))
    scene = rrb.Spatial3DView(name=ROOT, origin="/", contents=[f"/{ROOT}/**", *(f"- {f}" for f in frames)],
                              eye_controls=rrb.EyeControls3D(position=EYE, look_target=LOOK_AT, eye_up=(0, 0, 1)))
    views = rrb.Grid(*[rrb.Spatial2DView(name=c, origin=f) for c, f in zip(cameras, frames)])
    plots = rrb.Tabs(*[rrb.TimeSeriesView(name=p.removeprefix("signals/"), origin=p) for p in signals])
    log = rrb.TextLogView(name="phases and events", origin="/")
    top = rrb.Horizontal(scene, views) if cameras else scene
    return rrb.Blueprint(rrb.Vertical(top, rrb.Horizontal(plots, log, column_shares=[3, 1]), row_shares=[3, 2]))
