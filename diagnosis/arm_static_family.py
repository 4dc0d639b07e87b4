"""Static arm measurements as a diagnosis :class:`~serpar.diagnosis.family.Family`.

Nominal model: the Panda's MD-H table (:func:`serpar.kinematics.mdh.panda_chain`) with the recording's
nominal tool offset and rigid joints; for another arm (``--robot FILE``, ``data.robot``) its
table read from the model file, and the gravity torques of that file's own inertials. Baseline, always fitted: the tool point's offset and,
for laser-tracker data, the tracker's registration to the arm base (6). For point-consistency
data the socket centres are eliminated in closed form (each socket's centre is the mean of
its predicted points in the rows evaluated), so a held-out placement needs no fitted centre.

Candidate effects (:mod:`serpar.diagnosis.arm_static_model`): geometric, joint_compliance,
backlash, encoder, thermal_drift (with a time column). Each effect keeps only the parameters
the recording can tell apart from the baseline and from each other (a QR rank test on the
central-difference Jacobian at the start point): e.g. joint 1 carries no gravity load, so its
compliance is never a candidate.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping

import numpy as np
from numpy.typing import NDArray

from serpar.calibration.arm_static_data import StaticArmData
from serpar.diagnosis.arm_static_effects import candidate_effects, chain_rank, independent_columns
from serpar.diagnosis.arm_static_model import (
    element_jacobian,
    forward_rows,
    joint_effect,
    length_elements,
)
from serpar.diagnosis.family import Effect, LocateRow
from serpar.diagnosis.locate import locate_rows
from serpar.diagnosis.stability import default_folds
from serpar.diagnosis.units import UnitView, per_row
from serpar.errors import IdentificationError
from serpar.kinematics.mdh import panda_chain
from serpar.kinematics.robot import PANDA
from serpar.sim.plants.static_panda import TruthConfig, nominal_plant
from serpar.sim.robot_file import gravity_torques

BASELINE_PARAMS = {"position": ("base.tx", "base.ty", "base.tz", "base.rx", "base.ry",
                                "base.rz", "tool.tx", "tool.ty", "tool.tz"),
                   "point": ("tool.tx", "tool.ty", "tool.tz")}


class StaticArmFamily:
    """Laser-tracker positions or point-consistency sets of a serial arm (the Panda's 7 joints
    unless the data name another robot)."""

    def __init__(self, data: StaticArmData) -> None:
        self.data = data
        robot = data.robot
        arm = "" if robot is PANDA else f", {robot.label}"
        self.kind = (f"arm static ({'laser tracker' if data.kind == 'position' else 'point consistency'}"
                     f"{arm})")
        if robot is PANDA:
            self.chain = panda_chain(data.tool_offset_m)
            plant = nominal_plant(TruthConfig(tool_mass_kg=data.tool_mass_kg, hand=data.hand,
                                              tool_offset_m=data.tool_offset_m))
            gravity = plant.gravity_torques
        else:  # the file's own inertials: the model a controller of that arm would use
            self.chain = robot.chain(data.tool_offset_m)

            def gravity(q: NDArray[np.float64]) -> NDArray[np.float64]:
                return gravity_torques(robot, q)
        self.tau = gravity(data.q)
        """Nominal gravity torques [N m] at the commanded angles (the controller's model)."""
        h = 1e-6
        self.dtau = np.stack([(gravity(data.q + h * e) - gravity(data.q - h * e)) / (2 * h)
                              for e in np.eye(data.q.shape[1])], axis=2)
        """(N, n, n) d tau_g / dq at the commanded angles (central differences)."""
        # the two most loaded joints split the poses by gravity load (the Panda's j2 and j4)
        self.loaded = ((1, 3) if robot is PANDA else
                       tuple(sorted(np.argsort(-np.sqrt(np.mean(self.tau**2, axis=0)))[:2])))
        self.t = None if data.time is None else data.time - data.time.min()
        self.n_samples = data.n
        names = self.chain.names
        self.base_idx = np.array([names.index(n) for n in BASELINE_PARAMS[data.kind]])
        lengths = [n for n in BASELINE_PARAMS[data.kind] if n.startswith(("tool.t", "base.t"))]
        self.baseline: Effect | None = Effect(
            "baseline", "tool offset" + (" and tracker registration" if data.kind == "position"
                                         else ""),
            BASELINE_PARAMS[data.kind],
            tuple("m" if n in lengths else "rad" for n in BASELINE_PARAMS[data.kind]),
            np.zeros(len(self.base_idx)), np.full(len(self.base_idx), -0.5),
            np.full(len(self.base_idx), 0.5))
        self.lengths = length_elements(self.chain)
        self.geo_idx = np.zeros(0, int)
        self.param_names: dict[str, tuple[str, ...]] = {}
        """Parameter names of each effect (the full lists while the rank test runs)."""
        self.effects: tuple[Effect, ...] = candidate_effects(self)
        self.param_names = {e.name: e.param_names for e in self.effects}

    # -- the model -------------------------------------------------------------------------
    def _state(self, params: Mapping[str, NDArray[np.float64]], rows: NDArray[np.int64]):
        """Per-row element values (n, E), their thermal factor (n,), link angles (n, joints)
        and, per parameter of every joint-space block, d(link angles)/d(parameter)."""
        delta = np.zeros(self.chain.size)
        if "baseline" in params:
            delta[self.base_idx] += params["baseline"]
        if "geometric" in params:
            delta[self.geo_idx] += params["geometric"]
        values = np.tile(self.chain.values(delta), (len(rows), 1))
        factor = np.ones(len(rows))
        if "thermal_drift" in params and self.t is not None:
            factor = 1.0 + params["thermal_drift"][0] * self.t[rows]
            values[:, self.lengths] *= factor[:, None]
        q = self.data.q[rows]
        link, dlink = q.copy(), {}
        approach = None if self.data.approach is None else self.data.approach[rows]
        for name, p in params.items():
            if name not in ("baseline", "geometric", "thermal_drift"):
                offset, dlink[name] = joint_effect(name, self.param_names[name], p, q,
                                                   self.tau[rows], approach, self.dtau[rows])
                link += offset
        return values, factor, link, dlink

    def tool_points(self, params: Mapping[str, NDArray[np.float64]], rows: NDArray[np.int64]
                    ) -> NDArray[np.float64]:
        """(n, 3) predicted tool points of ``rows`` under the given blocks."""
        values, _, link, _ = self._state(params, np.asarray(rows, np.int64))
        return forward_rows(self.chain, values, link)

    def jacobian(self, params: Mapping[str, NDArray[np.float64]], rows: NDArray[np.int64],
                 skip: Collection[str] = ()) -> NDArray[np.float64]:
        """Exact d residual / d parameters, columns in the order of ``params`` (the engine's
        optional fast path; the screw form of serpar.kinematics.mdh: u x (p - o) or u per element)."""
        rows = np.asarray(rows, np.int64)
        values, factor, link, dlink = self._state(params, rows)
        p, g = element_jacobian(self.chain, values, link)          # (n, 3), (n, 3, E)
        gq = g[:, :, self.chain.joint_elements]                    # (n, 3, joints)
        scaled = np.ones_like(values)
        scaled[:, self.lengths] = factor[:, None]
        cols = []
        for name in params:  # the blocks in ``skip`` left out
            if name in skip:
                continue
            if name == "baseline":
                cols.append(g[:, :, self.base_idx] * scaled[:, None, self.base_idx])
            elif name == "geometric":
                cols.append(g[:, :, self.geo_idx] * scaled[:, None, self.geo_idx])
            elif name == "thermal_drift":
                v0 = values[:, self.lengths] / factor[:, None]
                t = np.zeros(len(rows)) if self.t is None else self.t[rows]
                cols.append(np.einsum("nae,ne->na", g[:, :, self.lengths], v0 * t[:, None])[..., None])
            else:
                cols.append(np.einsum("naj,knj->nak", gq, dlink[name]))
        jp = np.concatenate(cols, axis=2) if cols else np.zeros((len(rows), 3, 0))
        if self.data.kind == "position":
            return jp.reshape(len(rows) * 3, -1) / self.data.sigma_m
        return self._point_jacobian(p, jp, rows)

    def _point_jacobian(self, p: NDArray[np.float64], jp: NDArray[np.float64],
                        rows: NDArray[np.int64]) -> NDArray[np.float64]:
        d = self.data
        sock = d.socket[rows]  # type: ignore[index]
        out = np.zeros_like(jp)
        centres = {}
        for s in np.unique(sock):
            m = sock == s
            n = int(m.sum())
            c, jc = p[m].mean(axis=0), jp[m].mean(axis=0)
            centres[int(s)] = (c, jc, n)
            if n > 1:
                out[m] = (jp[m] - jc) / (d.sigma_m * np.sqrt(1.0 - 1.0 / n))
        extra = []
        for a, b, _ in d.distances:
            if a in centres and b in centres:
                (ca, ja, na), (cb, jb, nb) = centres[a], centres[b]
                u = (ca - cb) / max(np.linalg.norm(ca - cb), 1e-300)
                extra.append(u @ (ja - jb) / (d.sigma_m * np.sqrt(1.0 + 1.0 / na + 1.0 / nb)))
        flat = out.reshape(len(rows) * 3, -1)
        return np.vstack([flat, *[e[None, :] for e in extra]]) if extra else flat

    # -- Family protocol ------------------------------------------------------------------
    def residual(self, params: Mapping[str, NDArray[np.float64]], rows: NDArray[np.int64]
                 ) -> NDArray[np.float64]:
        rows = np.asarray(rows, np.int64)
        p = self.tool_points(params, rows)
        d = self.data
        if d.kind == "position":
            return ((p - d.position[rows]) / d.sigma_m).ravel()  # type: ignore[index]
        return self._point_residual(p, rows)

    def _point_residual(self, p: NDArray[np.float64], rows: NDArray[np.int64]
                        ) -> NDArray[np.float64]:
        d = self.data
        sock = d.socket[rows]  # type: ignore[index]
        r = np.zeros_like(p)
        centres: dict[int, tuple[NDArray[np.float64], int]] = {}
        for s in np.unique(sock):
            m = sock == s
            n = int(m.sum())
            c = p[m].mean(axis=0)
            centres[int(s)] = (c, n)
            if n > 1:  # p_i - mean has variance sigma^2 (1 - 1/n): rescale to unit variance
                r[m] = (p[m] - c) / (d.sigma_m * np.sqrt(1.0 - 1.0 / n))
        extra = []
        for a, b, dist in d.distances:
            if a in centres and b in centres:
                (ca, na), (cb, nb) = centres[a], centres[b]
                s = d.sigma_m * np.sqrt(1.0 + 1.0 / na + 1.0 / nb)  # fixture + centre noise
                extra.append((np.linalg.norm(ca - cb) - dist) / s)
        return np.concatenate([r.ravel(), np.asarray(extra, float)])

    def in_units(self, rows: NDArray[np.int64]) -> UnitView:
        """x, y, z of each measured tool point in mm (position data: against the tracker;
        point data: about its socket's mean), then each fixture distance in mm."""
        rows = np.asarray(rows, np.int64)
        d = self.data
        channel, axis = per_row(rows.astype(float), 3)
        mm = 1e3 * d.sigma_m
        if d.kind == "position":
            return UnitView(("x", "y", "z"), ("mm",) * 3, channel, np.full(3 * len(rows), mm),
                            axis, "measurement", 1e3 * d.position[rows].ravel())  # type: ignore[index]
        sock = d.socket[rows]  # type: ignore[index]
        count = {int(s): int((sock == s).sum()) for s in np.unique(sock)}
        scale = np.repeat([mm * np.sqrt(max(1.0 - 1.0 / count[int(s)], 0.0)) for s in sock], 3)
        extra = [mm * np.sqrt(1.0 + 1.0 / count[a] + 1.0 / count[b])
                 for a, b, _ in d.distances if a in count and b in count]
        return UnitView(("x", "y", "z", "fixture distance"), ("mm",) * 4,
                        np.r_[channel, np.full(len(extra), 3)], np.r_[scale, extra],
                        np.r_[axis, np.full(len(extra), float(rows.mean()))], "measurement")

    def split(self, rng: np.random.Generator) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """The campaign's own train/verify sets; else leave one fixture placement out; else
        the last third in time; else a random third of the poses (per socket)."""
        d, idx = self.data, np.arange(self.data.n)
        if d.split is not None:
            train, held = idx[d.split == "train"], idx[d.split == "verify"]
            if train.size and held.size:
                return train, held
        if d.placement is not None and len(set(d.placement.tolist())) >= 2:
            held_place = rng.choice(sorted(set(d.placement.tolist())))
            return idx[d.placement != held_place], idx[d.placement == held_place]
        if self.t is not None:
            order = np.argsort(self.t, kind="stable")
            cut = round(2 * d.n / 3)
            return np.sort(order[:cut]), np.sort(order[cut:])
        groups = d.socket if d.kind == "point" else np.zeros(d.n, int)
        held = np.concatenate([rng.permutation(idx[groups == g])[:int(np.sum(groups == g)) // 3]
                               for g in np.unique(groups)])
        return np.setdiff1d(idx, held), np.sort(held)

    def folds(self, k: int) -> list[tuple[NDArray[np.int64], NDArray[np.int64]]]:
        """Resampling folds: with two or more fixture placements, each placement held out in
        turn (what holds up must hold up on every placement the split could hold out); else
        the engine's default folds over the rows."""
        d, idx = self.data, np.arange(self.data.n)
        if d.placement is None or len(set(d.placement.tolist())) < 2:
            return default_folds(self.n_samples, k)
        return [(idx[d.placement != p], idx[d.placement == p])
                for p in sorted(set(d.placement.tolist()))]

    def locate(self, rows: NDArray[np.int64], whitened: NDArray[np.float64]) -> list[LocateRow]:
        rows = np.asarray(rows, np.int64)
        w = np.asarray(whitened, float)[:3 * len(rows)].reshape(len(rows), 3)
        d = self.data
        groups: list[tuple[str, str, str, NDArray[np.float64]]] = []
        for a, axis in enumerate("xyz"):
            groups.append((f"tool {axis}", "all", "all poses", w[:, a]))
        a, b = self.loaded
        load = np.abs(self.tau[rows, a]) + np.abs(self.tau[rows, b])
        cut = np.median(load)
        joints = f"j{a + 1}+j{b + 1}"
        groups.append(("tool xyz", "regime", f"high gravity load ({joints})", w[load > cut].ravel()))
        groups.append(("tool xyz", "regime", f"low gravity load ({joints})", w[load <= cut].ravel()))
        if d.approach is not None:
            for sign, label in ((1.0, "approach from below"), (-1.0, "approach from above")):
                m = d.approach[rows].sum(axis=1) * sign > 0
                groups.append(("tool xyz", "regime", label, w[m].ravel()))
        if self.t is not None:
            t = self.t[rows]
            edges = np.quantile(t, [0, 1 / 3, 2 / 3, 1])
            for k in range(3):
                m = (t >= edges[k]) & (t <= edges[k + 1]) if k == 2 else (t >= edges[k]) & (t < edges[k + 1])
                groups.append(("tool xyz", "time", f"t {edges[k]:.0f}-{edges[k + 1]:.0f} s", w[m].ravel()))
        if d.split is not None:
            for s in ("train", "verify"):
                groups.append(("tool xyz", "set", s, w[d.split[rows] == s].ravel()))
        if d.kind == "point":
            for s in np.unique(d.socket[rows]):  # type: ignore[index]
                label = (f"placement {d.placement[rows][d.socket[rows] == s][0]}"  # type: ignore[index]
                         if d.placement is not None else "")
                groups.append((f"socket {s}", "socket", label or "all poses",
                               w[d.socket[rows] == s].ravel()))  # type: ignore[index]
        return locate_rows(groups)


def family_from_data(data: StaticArmData) -> StaticArmFamily:
    if data.n < 10:
        raise IdentificationError(f"{data.n} measured poses; a diagnosis needs at least 10")
    return StaticArmFamily(data)


__all__ = ["StaticArmFamily", "chain_rank", "family_from_data", "independent_columns"]
