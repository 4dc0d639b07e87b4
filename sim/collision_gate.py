"""Keep the plate's and the tray's ~800 geoms out of MuJoCo's broad phase while nothing can reach them.

MuJoCo's broad phase builds a bounding box for every geom of every body that can collide, on
every step: with the plate's 627 bore and bar geoms and the tray's 157 pocket geoms that is
~11 of the ~35 us a free-motion step of the cell costs, whether or not anything is near them
(switching the geoms' contype off does not help: the broad phase keys on the *body's*
contype/conaffinity, compiled as the OR of its geoms'). So at each :meth:`CollisionGate.update`
(the runtime calls it every few control periods) the gate looks at every other collidable geom
and, for each gated group (a body and what is welded to it in its subtree: the plate with its
seated parts, the tray), zeroes the group's body-level contype/conaffinity while no geom can
reach the group before the next update, and restores the compiled values as soon as one can.

It changes no contact: a group is off only while every other geom's bounding sphere (MuJoCo's
own: geom_xpos, geom_rbound) lies farther from the group's bounding box than `reach` plus three
times what anything moved since the last update, so no contact (margins included) could have
formed. The broad phase sorts its
pairs by body id, so the contact list, and with it the whole trajectory, is bit-identical to
the ungated cell (tests/test_collision_gate.py).

Sleeping bodies: a static group (the tray, welded to the world) ignores bodies that are
asleep, since they cannot move until an awake body touches them, and an awake body near the
group turns it on first. A moving group (the plate on the platform) counts sleeping bodies as
well: a part asleep on it must keep its contact to be woken and carried when the platform moves.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from serpar.sim.physics import AWAKE

REACH = 0.01
"""Gap [m] below which a body counts as able to reach a gated group in the coming period (on
top of three times the largest displacement in the last one)."""

_BOX_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


def _geom_corners(model: mujoco.MjModel, data: mujoco.MjData, geoms: np.ndarray) -> np.ndarray:
    """World coordinates of the 8 corners of each geom's bounding box (n, 8, 3), margins in."""
    aabb = model.geom_aabb[geoms]
    half = aabb[:, 3:] + (model.geom_margin[geoms] + model.geom_gap[geoms])[:, None]
    local = aabb[:, None, :3] + _BOX_CORNERS[None] * half[:, None, :]
    rot = data.geom_xmat[geoms].reshape(-1, 3, 3)
    return np.einsum("gij,gcj->gci", rot, local) + data.geom_xpos[geoms][:, None, :]


@dataclass
class _Group:
    root: int
    bodies: np.ndarray
    contype: np.ndarray
    conaffinity: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    """Bounding box of the group's geoms in the root body's frame."""
    static: bool
    on: bool = True


class CollisionGate:
    """Switches the named bodies' groups in and out of collision detection (see module doc)."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, roots: tuple[str, ...],
                 reach: float = REACH) -> None:
        if reach <= 0:
            raise ValueError(f"reach {reach} m: must be > 0")
        self.reach = reach
        self.switches = 0
        """How often a group was switched on or off (a health figure for the bench)."""
        self._roots = roots
        self.bind(model, data)

    def bind(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        """(Re)build the groups for a freshly compiled model (all groups on, as compiled)."""
        self.model = model
        mujoco.mj_kinematics(model, data)
        self.groups = [self._group(model, data, model.body(name).id) for name in self._roots]
        grouped = np.concatenate([g.bodies for g in self.groups])
        # Every collidable geom of the other bodies, as MuJoCo's own bounding sphere (geom_xpos,
        # geom_rbound): a body's sphere about its origin would be far larger for an arm link.
        body = model.geom_bodyid
        self._others = np.flatnonzero((body > 0) & ~np.isin(body, grouped)
                                      & ((model.geom_contype != 0) | (model.geom_conaffinity != 0)))
        self._other_bodies = body[self._others]
        self._radius = model.geom_rbound[self._others] + model.geom_margin[self._others]
        world = np.flatnonzero(model.geom_bodyid == 0)
        is_plane = model.geom_type[world] == mujoco.mjtGeom.mjGEOM_PLANE
        self._planes = world[is_plane]
        fixed = world[~is_plane]  # the world body's own geoms (pedestal, posts): spheres in place
        self._fixed_centres = data.geom_xpos[fixed].copy()
        self._fixed_radius = model.geom_rbound[fixed] + model.geom_margin[fixed]
        self._touch = [self._can_touch(model, g) for g in self.groups]
        self._last_pos: np.ndarray | None = None
        self._last_corners: list[np.ndarray] = []

    @staticmethod
    def _group(model: mujoco.MjModel, data: mujoco.MjData, root: int) -> _Group:
        weld = model.body_weldid[root]
        bodies = [b for b in range(model.nbody)
                  if model.body_weldid[b] == weld and _in_subtree(model, b, root) and model.body_geomnum[b]]
        geoms = np.concatenate([np.arange(model.body_geomadr[b], model.body_geomadr[b] + model.body_geomnum[b])
                                for b in bodies])
        corners = _geom_corners(model, data, geoms).reshape(-1, 3)
        rot = data.xmat[root].reshape(3, 3)
        local = (corners - data.xpos[root]) @ rot
        b = np.array(bodies, int)
        return _Group(root, b, model.body_contype[b].copy(), model.body_conaffinity[b].copy(),
                      local.min(axis=0), local.max(axis=0), static=bool(weld == 0))

    def _can_touch(self, model: mujoco.MjModel, g: _Group) -> np.ndarray:
        """Which of the other geoms MuJoCo's filters would let collide with the group at all
        (another weld, not its weld parent or child, compatible contype/conaffinity bits)."""
        o = self._other_bodies
        weld = model.body_weldid[g.root]
        parent = model.body_weldid[model.body_parentid[weld]]
        o_weld = model.body_weldid[o]
        o_parent = model.body_weldid[model.body_parentid[o_weld]]
        filter_parent = not model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_FILTERPARENT
        related = (o_weld == weld) | (filter_parent & (weld != 0) & (o_weld != 0)
                                       & ((o_weld == parent) | (o_parent == weld)))
        ctype, caff = np.bitwise_or.reduce(g.contype), np.bitwise_or.reduce(g.conaffinity)
        geoms = self._others
        bits = ((model.geom_contype[geoms] & caff) | (ctype & model.geom_conaffinity[geoms])) != 0
        return ~related & bits

    def update(self, data: mujoco.MjData) -> None:
        """Decide which groups take part in collision detection until the next update."""
        pos = data.geom_xpos[self._others]
        last, self._last_pos = self._last_pos, pos
        if last is None:  # no motion seen yet to size the margin: everything stays as it is
            self._last_corners = [self._box_corners(g, data.xpos[g.root], data.xmat[g.root].reshape(3, 3))
                                  for g in self.groups]
            return
        moved = float(np.sqrt(np.max(np.sum((pos - last) ** 2, axis=1))))
        awake = data.body_awake[self._other_bodies] == AWAKE
        for i, g in enumerate(self.groups):
            rot = data.xmat[g.root].reshape(3, 3)
            corners = self._box_corners(g, data.xpos[g.root], rot)
            last_corners, self._last_corners[i] = self._last_corners[i], corners
            group_moved = float(np.max(np.abs(corners - last_corners))) * 1.7321  # |d| <= sqrt(3) max|d_i|
            margin = self.reach + 3.0 * (moved + group_moved)
            candidates = self._touch[i] & awake if g.static else self._touch[i]
            reach = margin + self._radius[candidates]
            near = bool(np.any(_gap_sq(g, pos[candidates], data.xpos[g.root], rot) < reach * reach))
            if not (near or g.static):
                near = self._near_fixed(g, data, rot, corners, margin)
            if near != g.on:
                self._switch(self.model, g, near)

    def _near_fixed(self, g: _Group, data: mujoco.MjData, rot: np.ndarray, corners: np.ndarray,
                    margin: float) -> bool:
        """A moving group near the world body's geoms (the floor plane, pedestals, posts)."""
        reach = margin + self._fixed_radius
        if np.any(_gap_sq(g, self._fixed_centres, data.xpos[g.root], rot) < reach * reach):
            return True
        for plane in self._planes:
            normal = data.geom_xmat[plane].reshape(3, 3)[:, 2]
            if np.min((corners - data.geom_xpos[plane]) @ normal) < margin:
                return True
        return False

    def _switch(self, m: mujoco.MjModel, g: _Group, on: bool) -> None:
        m.body_contype[g.bodies] = g.contype if on else 0
        m.body_conaffinity[g.bodies] = g.conaffinity if on else 0
        g.on = on
        self.switches += 1

    def any_on(self) -> bool:
        return any(g.on for g in self.groups)

    def set_on(self, on: np.ndarray) -> None:
        """Put each group in (True) or out as given (a replay of recorded decisions)."""
        for g, want in zip(self.groups, on):
            if bool(want) != g.on:
                self._switch(self.model, g, bool(want))

    def reset(self) -> None:
        """Every group back in, as compiled, and the motion history forgotten (after the state
        jumped: a restored snapshot)."""
        for g in self.groups:
            if not g.on:
                self._switch(self.model, g, True)
        self._last_pos = None

    @staticmethod
    def _box_corners(g: _Group, origin: np.ndarray, rot: np.ndarray) -> np.ndarray:
        centre, half = (g.lo + g.hi) / 2, (g.hi - g.lo) / 2
        return (centre + _BOX_CORNERS * half) @ rot.T + origin


def _gap_sq(g: _Group, points: np.ndarray, origin: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Squared distance of each world point from the group's box (0 inside)."""
    local = (points - origin) @ rot
    outside = np.maximum(0.0, np.maximum(g.lo - local, local - g.hi))
    return np.sum(outside * outside, axis=1)


def _in_subtree(model: mujoco.MjModel, body: int, root: int) -> bool:
    while body > 0:
        if body == root:
            return True
        body = model.body_parentid[body]
    return root == 0
