"""The insertion trials on MuJoCo Warp (``serpar montecarlo --gpu``): the part of
``mujoco.batch.Batch`` that tasks/insertion_batch.py uses, over ``mujoco_warp`` worlds.

The runner, the controller and the trial logic stay the CPU path's, one code; this engine
only steps the plant. Per control period the host uploads the substeps' commands, the
device runs the period's substeps (captured once as a CUDA graph: a kernel sets each
substep's command, one records each substep's sensors) and the host reads the state back.
The controller therefore runs on the host once per period, not inside the graph: one
implementation of the control law, at the price of a round trip every period (not every
step).

Per-trial dimensions without a model per world: each trial's compiled model gives its
world the fields that differ between trials (journal and body radii, the part's mass and
inertia and what the compiler derives from them). Meshes are shared (the engine's model's):
the bore facets are moved radially so that each world's inner faces sit at its hole's
radius (within 0.1 um), and the journal tip is the thinnest journal's.

MuJoCo Warp is float32: run the GPU's trial scene (checks/montecarlo_gpu.py ``gpu_scene``:
the origin at the hole, softer pads, the seat a plane, the part's edges rounded), each change
for a float32 failure traced in docs/montecarlo.md ("On a GPU").
"""

from __future__ import annotations

import ctypes.util
import logging
from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import NDArray

from serpar.errors import ConfigError

WRITABLE = ("qpos", "qvel", "ctrl", "mocap_pos")
"""Fields the runner writes between calls: uploaded before every device call."""
PER_WORLD = ("geom_size", "geom_pos", "geom_quat", "geom_rbound", "geom_aabb", "body_mass",
             "body_subtreemass", "body_inertia", "body_ipos", "body_iquat", "body_invweight0",
             "dof_invweight0")
"""Model fields that differ between trials' models and MuJoCo Warp takes per world."""
INSTALL = "pip install 'serpar[gpu]' (mujoco-warp, warp-lang)"
EPA_HORIZON_EDGES = 128
"""Edges MuJoCo Warp's EPA may keep on a polytope's horizon. Its default, 24, overflows on the
journal tip's and the bore facets' meshes on a GPU, and an overflowing pair gets no contact for
that step (a seated journal drops into the bore, then is kicked out of a deep penetration)."""


def load_warp() -> tuple[object, object]:
    """(warp, mujoco_warp), or ConfigError saying how to install them."""
    try:
        import warp
        warp.config.log_level = logging.WARNING  # its start-up banner would go to stdout, ahead of --json
        import mujoco_warp
        from mujoco_warp._src import (
            collision_convex,  # the buffer is sized from this module constant
        )
    except ImportError as exc:
        raise ConfigError(f"--gpu needs MuJoCo Warp ({exc.name} is not installed): {INSTALL}") from None
    collision_convex.MJ_MAX_EPAHORIZON = max(collision_convex.MJ_MAX_EPAHORIZON, EPA_HORIZON_EDGES)
    return warp, mujoco_warp


def check_device(device: str) -> str:
    """``cuda`` (the default GPU) or ``cpu`` (warp's CPU backend, for tests): ConfigError when
    the device does not exist here."""
    if device not in ("cuda", "cpu"):
        raise ConfigError(f"device {device!r}; valid: cuda, cpu")
    no_gpu = ConfigError("--gpu: no CUDA device on this machine; run without --gpu for the CPU cores")
    if device == "cuda" and ctypes.util.find_library("cuda") is None:
        raise no_gpu  # no driver: said before warp starts (and warns of it on stderr)
    wp, _ = load_warp()
    if device == "cuda" and wp.get_cuda_device_count() == 0:  # type: ignore[attr-defined]
        raise no_gpu
    return device


class WarpBatch:
    """``n`` worlds of ``model`` on ``device``; the calls and arrays of ``mujoco.batch.Batch``
    that run_trials uses (bind, set_models, reset, forward, rollout, status, warning, error)."""

    def __init__(self, model: mujoco.MjModel, n: int, device: str = "cuda",
                 contacts_per_world: int = 64, constraints_per_world: int = 512) -> None:
        self.wp, self.mjw = load_warp()
        wp, mjw = self.wp, self.mjw
        self.model, self.n, self.device = model, n, check_device(device)
        with wp.ScopedDevice(device):  # type: ignore[attr-defined]
            self.m = mjw.put_model(model, batch_sizes=dict.fromkeys(PER_WORLD, n))  # type: ignore[attr-defined]
            self.d = mjw.make_data(model, nworld=n, nconmax=contacts_per_world,  # type: ignore[attr-defined]
                                   njmax=constraints_per_world)
        # the float32 solver often stops at its iteration limit short of the tolerance:
        # counted here (iteration_limit) instead of printed to stdout on every step
        # and EPA's horizon buffer overflows are counted (epa_overflow), not printed per step
        self._epa = int(mjw.OverflowType.EPA_HORIZON)  # type: ignore[attr-defined]
        quiet = int(mjw.OverflowType.ITERATIONS) | int(mjw.OverflowType.LS_ITERATIONS) | self._epa  # type: ignore[attr-defined]
        self.m.opt.warn_overflow = int(self.m.opt.warn_overflow) & ~quiet
        self.iteration_limit = 0
        """World-periods whose last step stopped at the solver's iteration limit."""
        self.epa_overflow = 0
        """World-periods in which a mesh pair's EPA horizon overflowed (that pair had no contact)."""
        self.world_periods = 0
        self._host: dict[str, NDArray[np.float64]] = {}
        self.status = np.zeros(n, dtype=np.int32)
        self.warning = np.zeros((n, int(mujoco.mjtWarning.mjNWARNING), 2), dtype=np.int32)
        self._graphs: dict[int, object] = {}
        self._ctrl_buf = self._rec_buf = None
        self._models: list[mujoco.MjModel] = [model] * n

    # -- arrays --------------------------------------------------------------------------
    def bind(self, name: str) -> NDArray[np.float64]:
        """The (n, ...) host copy of a data field, refreshed after every device call."""
        if name not in self._host:
            self._host[name] = np.asarray(getattr(self.d, name).numpy(), dtype=float).copy()
        return self._host[name]

    def _upload(self) -> None:
        for name in WRITABLE:
            if name in self._host:
                getattr(self.d, name).assign(self._host[name].astype(np.float32))

    def _download(self) -> None:
        for name, host in self._host.items():
            host[...] = getattr(self.d, name).numpy()

    def set_models(self, models: Sequence[mujoco.MjModel]) -> None:
        """Each world takes its trial model's per-world fields (PER_WORLD); meshes stay the
        first model's."""
        changed = [i for i, (a, b) in enumerate(zip(self._models, models)) if a is not b]
        if not changed:
            return
        self._models = list(models)
        poses = {i: _mesh_geom_poses(self.model, models[i]) for i in changed}
        for name in PER_WORLD:
            field = getattr(self.m, name)
            values = field.numpy()
            for i in changed:
                own = poses[i].get(name) if name in ("geom_pos", "geom_quat") else None
                values[i] = (own if own is not None else
                             np.asarray(getattr(models[i], name)).reshape(values[i].shape))
            field.assign(values)

    # -- calls ---------------------------------------------------------------------------
    def reset(self, ids: NDArray[np.intp], stage: object = None) -> None:
        mask = np.zeros(self.n, dtype=bool)
        mask[np.asarray(ids)] = True
        self._upload()
        self.mjw.reset_data(self.m, self.d, reset=self.wp.array(mask, dtype=bool, device=self.device))  # type: ignore[attr-defined]
        self._download()
        self.warning[mask] = 0

    def forward(self, ids: NDArray[np.intp] | None = None) -> None:
        self._upload()
        self.mjw.forward(self.m, self.d)  # type: ignore[attr-defined]
        self._download()

    def rollout(self, nstep: int, control: NDArray[np.float64], record: Sequence[str] = (),
                ids: NDArray[np.intp] | None = None) -> dict[str, NDArray[np.float64]]:
        """``nstep`` steps of every world, the worlds ``ids`` under ``control`` (len(ids) x nstep
        x nu), the others holding their command; the recorded fields of ``ids`` per step."""
        wp = self.wp
        ids = np.arange(self.n) if ids is None else np.asarray(ids)
        if tuple(record) not in ((), ("sensordata",)):
            raise ConfigError(f"WarpBatch records sensordata only, not {record}")
        ctrl = self.bind("ctrl")
        full = np.repeat(ctrl[None], nstep, axis=0)  # step x world x nu
        full[:, ids] = np.swapaxes(control, 0, 1)
        self._buffers(nstep)
        self._ctrl_buf.assign(full.astype(np.float32))  # type: ignore[union-attr]
        self._upload()
        # the state just uploaded, from the host copies (no read back from the device)
        start = (self.bind("qpos").astype(np.float32), self.bind("qvel").astype(np.float32))
        if self.device == "cuda":
            if nstep not in self._graphs:
                with wp.ScopedCapture(device=self.device) as capture:  # type: ignore[attr-defined]
                    self._steps(nstep)
                self._graphs[nstep] = capture.graph
            wp.capture_launch(self._graphs[nstep])  # type: ignore[attr-defined]
        else:
            with wp.ScopedDevice(self.device):  # type: ignore[attr-defined]
                self._steps(nstep)
        broken = self._contain(ids, start)
        self._download()
        self.iteration_limit += int((self.d.solver_niter.numpy() >= self.model.opt.iterations).sum())
        self.epa_overflow += int(((self.d.overflow.numpy() & self._epa) != 0).sum())
        self.d.overflow.zero_()
        self.world_periods += self.n
        ctrl[...] = full[-1]
        if not record:
            return {}
        rec = self._rec_buf.numpy()[:nstep]  # type: ignore[union-attr]
        rec[:, broken] = 0.0  # as MuJoCo's batch gives a failed simulation's period
        return {"sensordata": np.swapaxes(rec, 0, 1)[ids].astype(float)}

    def _contain(self, ids: NDArray[np.intp],
                 start: tuple[NDArray[np.float32], NDArray[np.float32]]) -> NDArray[np.bool_]:
        """Do what MuJoCo's batch does for a diverged simulation, and hold idle worlds still:
        every world steps in every call and shares the batch's collision and solver passes. A
        world that went non-finite is put back at its ``start`` (the call's first state) and
        counted as a warning (mjWARN_BADQACC; the runner's health check ends its trial); not
        reset to qpos0, where the arm is singular and the controller's next update would fail
        over the whole batch. A world outside ``ids`` is put back at its start too. Returns the
        broken worlds."""
        qpos, qvel = self.d.qpos.numpy(), self.d.qvel.numpy()
        broken = ~(np.isfinite(qpos).all(axis=1) & np.isfinite(qvel).all(axis=1))
        back = np.ones(self.n, dtype=bool)
        back[ids] = False
        back |= broken
        if back.any():
            qpos[back], qvel[back] = start[0][back], start[1][back]
            self.d.qpos.assign(qpos)
            self.d.qvel.assign(qvel)
        if broken.any():
            self.warning[broken, int(mujoco.mjtWarning.mjWARN_BADQACC), 0] += 1
        return broken

    def _buffers(self, nstep: int) -> None:
        wp = self.wp
        shape = (nstep, self.n)
        if self._ctrl_buf is None or self._ctrl_buf.shape[0] < nstep:
            self._ctrl_buf = wp.zeros((*shape, self.model.nu), dtype=float, device=self.device)  # type: ignore[attr-defined]
            self._rec_buf = wp.zeros((*shape, self.model.nsensordata), dtype=float, device=self.device)  # type: ignore[attr-defined]
            self._graphs.clear()

    def _steps(self, nstep: int) -> None:
        wp, mjw = self.wp, self.mjw
        for s in range(nstep):
            wp.copy(self.d.ctrl, self._ctrl_buf[s])  # type: ignore[attr-defined,index]
            mjw.step(self.m, self.d)  # type: ignore[attr-defined]
            wp.copy(self._rec_buf[s], self.d.sensordata)  # type: ignore[attr-defined,index]

    def error(self, i: int) -> str:
        return ""


def mesh_vertices(model: mujoco.MjModel, g: int) -> NDArray[np.float64]:
    """Geom ``g``'s mesh vertices in its body's frame."""
    k = model.geom_dataid[g]
    v = model.mesh_vert[model.mesh_vertadr[k]:model.mesh_vertadr[k] + model.mesh_vertnum[k]]
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, model.geom_quat[g])
    return v @ rot.reshape(3, 3).T + model.geom_pos[g]


def _mesh_geom_poses(shared: mujoco.MjModel, own: mujoco.MjModel) -> dict[str, NDArray[np.float64]]:
    """geom_pos and geom_quat for the shared meshes in ``own``'s world.

    A bore facet's mesh is the wall between the hole and the plate's window, so its centroid
    moves by half the hole's radius change while its inner face moves by all of it: the shared
    facet is moved radially by the change of the inner face's radius (own's against shared's,
    measured on the meshes), which puts the inner face where own's is. The journal tip's mesh is
    the thinnest journal's (checks/montecarlo_gpu.py ``reference_model``): moved along the
    journal's axis (-z) by the radius change, its 45 deg chamfer lies on own's, tangent to own's
    edge round (sim/conductor.py), its end up to 3 um below own's."""
    pos, quat = shared.geom_pos.copy(), shared.geom_quat.copy()
    for g in np.flatnonzero(shared.geom_type == mujoco.mjtGeom.mjGEOM_MESH):
        centre = shared.geom_pos[g, :2]
        radius = float(np.hypot(*centre))
        if radius < 1e-9:  # on its body's axis: the journal tip
            ring = [float(np.max(np.hypot(*mesh_vertices(m, g)[:, :2].T))) for m in (own, shared)]
            pos[g, 2] -= ring[0] - ring[1]
            continue
        inner = [float(np.min(np.hypot(*mesh_vertices(m, g)[:, :2].T))) for m in (own, shared)]
        pos[g, :2] = centre + (inner[0] - inner[1]) * centre / radius
    return {"geom_pos": pos, "geom_quat": quat}
