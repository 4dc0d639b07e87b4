"""Solver and contact settings: the single source of truth for the timestep.

Why these numbers: the journal/bore radial clearance is 0-8 um, so contact
penetration must stay well below 1 um. MuJoCo's soft contact settles at a
penetration ~ F * A * (1 - d) / (d * k) (A: inverse effective mass, d: solimp
impedance, k: solref stiffness), so the precision contacts use an impedance
close to 1 and the stiffest time constant the timestep allows (2 * dt).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco

from serpar.errors import ConfigError


@dataclass(frozen=True)
class PhysicsConfig:
    """Global MuJoCo options of every serpar scene."""

    timestep: float = 1e-4
    """Physics step [s]. The only place the timestep is defined."""
    transit_timestep: float | None = 2.5e-4
    """Physics step [s] while nothing precise can happen: no body within reach of the plate or
    the tray (sim/transit_step.py); None = always `timestep`. At most half the pads' normal time
    constant; the control period must be a whole number of it."""
    iterations: int = 100
    ls_iterations: int = 50
    tolerance: float = 1e-10
    ccd_tolerance: float = 1e-10
    """Convex-collision tolerance [m]; the default 1e-6 is the size of the clearance."""
    impratio: float = 100.0
    precision_solimp: tuple[float, float, float, float, float] = (0.995, 0.99999, 2e-6, 0.5, 2.0)
    """solimp of journal/bore contacts: full stiffness reached at 2 um penetration."""
    precision_timeconst: float | None = None
    """solref time constant of journal/bore contacts [s]; None = 2 * timestep, the stiffest stable."""
    precision_dampratio: float = 1.0
    precision_friction: float = 0.2
    """Sliding friction between journal and bore (steel on brass, dry-ish)."""
    grip_timesteps: float = 5.0
    """solref time constant of the gripper pads' normal direction, in timesteps (at 2 steps a
    light part pressed off-axis onto the plate spins up and blows up). The pads' friction rows
    have their own damping, :attr:`grip_friction_damping`."""
    grip_friction_damping: float = 1.5
    """Damping b of the friction rows of the pad/conductor contacts, as b * timestep (MuJoCo
    solreffriction in direct form, set on explicit pad/conductor pairs). MuJoCo's constraint
    acceleration leaves out the velocity-product term Jdot*qvel, and a friction row has no
    position memory, so a part held by pads on the arm's joint chain drifts at
    Jdot*qvel * (1/b - timestep/2) (measured within 3 %): 0.11 mm/s at 0.5 m/s with b = 2/(5 dt),
    the old pad time constant. b = 2/timestep cancels the drift to first order but is the
    stability limit of the row's velocity update (the row's velocity flips sign each step,
    undamped); 1.5 leaves 1/12 of the old drift (1/3 of b = 1/timestep's) and halves a transient
    each step."""
    sleep: bool = True
    """MuJoCo island sleeping: parts at rest (conductors in the tray or seated) stop being
    integrated until something awake touches them. The arm never sleeps; the Stewart platform
    sleeps when still (serpar.sim.stewart.PLATFORM_SLEEP), and with it the parts seated in its plate.
    36 resting conductors otherwise cost 4x the step time of the empty cell."""
    sleep_tolerance: float = 1e-6
    """Velocity below which a tree may fall asleep [m/s, rotations weighted by dof_length].
    Not MuJoCo's default 1e-4: the leg servos converge with a ~70 ms time constant, so at
    1e-4 the still platform froze 4.3-4.8 um short of a 2 mm move; at 1e-6 it stops within
    0.05 um. Not lower: seated journals chatter in their bores at 2-8e-7 m/s and would never
    sleep (measured at 1e-7). Tray parts fall asleep within 0.1 s either way."""
    arm_friction_timeconst: float = 5e-4
    """solref time constant of the arm joints' dry friction rows (``frictionloss``) [s]: twice
    the transit step, the stiffest MuJoCo keeps unclamped. A friction row is soft: it pulls the
    joint's acceleration toward -v/tau, so a joint other torques decelerate faster than v/tau
    gets its dry friction pushed *along* its motion near a stop, which Coulomb friction never
    does. With MuJoCo's default 0.02 s the cell's joint 4, braked at 6 rad/s^2 from 0.05 rad/s,
    had its full Fc reversed within 2 ms, and the episode diagnosis read the cell's actuation
    latency ~10 us early (docs/sim2real.md); 5e-4 keeps it Coulomb down to ~1e-3 rad/s
    (tests/test_dry_friction.py)."""
    noslip_iterations: int = 10
    """MuJoCo's no-slip post-solve on friction: without it a soft friction constraint creeps,
    and a held part whose tip lands on the plate top rocks in the soft pads, spins up and
    breaks the integration (measured: hole 35 after hole 0, seed 0). Costs ~7 % step time."""

    def __post_init__(self) -> None:
        if not 1e-6 <= self.timestep <= 2e-3:
            raise ConfigError(f"timestep {self.timestep} s outside the valid range 1e-6..2e-3 s")
        if self.iterations < 1 or self.ls_iterations < 1:
            raise ConfigError("iterations and ls_iterations must be >= 1")
        if self.precision_timeconst is not None and self.precision_timeconst < 2 * self.timestep:
            raise ConfigError(f"precision_timeconst {self.precision_timeconst} s below 2*timestep "
                              f"({2 * self.timestep} s): MuJoCo would clamp it")
        if not 0 <= self.noslip_iterations <= 1000:
            raise ConfigError(f"noslip_iterations {self.noslip_iterations}: valid 0..1000 (0 = off)")
        if not 2.0 <= self.grip_timesteps <= 200.0:
            raise ConfigError(f"grip_timesteps {self.grip_timesteps}: valid 2..200")
        if self.transit_timestep is not None:
            limit = self.grip_timesteps * self.timestep / 2
            if not self.timestep <= self.transit_timestep <= limit * (1 + 1e-9):
                raise ConfigError(f"transit_timestep {self.transit_timestep} s: valid from timestep "
                                  f"({self.timestep} s) to half the pads' time constant ({limit:g} s), or null")
        finest = max(self.timestep, self.transit_timestep or 0.0)
        if not 2 * finest * (1 - 1e-9) <= self.arm_friction_timeconst <= 1.0:
            raise ConfigError(f"arm_friction_timeconst {self.arm_friction_timeconst} s: valid "
                              f"{2 * finest:g}..1 s (at least twice the largest physics step, "
                              "or MuJoCo clamps it)")
        if not 0.0 < self.grip_friction_damping < 2.0:
            raise ConfigError(f"grip_friction_damping {self.grip_friction_damping}: valid (0, 2) "
                              "(b * timestep; 2 is the stability limit of a friction row)")
        d0, dw, width = self.precision_solimp[:3]
        if not (0 < d0 <= dw < 1 and width > 0):
            raise ConfigError(f"precision_solimp {self.precision_solimp} needs 0<d0<=dwidth<1, width>0")

    @property
    def longest_step(self) -> float:
        """[s] The longest step the cell takes (explicit forces must stay stable at it)."""
        return max(self.timestep, self.transit_timestep or 0.0)

    @property
    def grip_solref(self) -> tuple[float, float]:
        """solref of the pads' contacts (normal direction): time constant, damping ratio."""
        return (self.grip_timesteps * self.timestep, 1.0)

    @property
    def grip_solreffriction(self) -> tuple[float, float]:
        """solreffriction of the pad/conductor pairs, direct form (-stiffness, -damping): a
        friction row has no stiffness, its damping is grip_friction_damping / timestep."""
        return (0.0, -self.grip_friction_damping / self.timestep)

    @property
    def transit_grip_solreffriction(self) -> tuple[float, float]:
        """The pads' friction damping at the transit step that leaves a held part the same drift
        Jdot*qvel * (1/b - h/2) as the fine step: 1/b = h_t/2 + (1/b0 - h0/2)."""
        assert self.transit_timestep is not None
        b0 = self.grip_friction_damping / self.timestep
        inverse = self.transit_timestep / 2 + (1 / b0 - self.timestep / 2)
        return (0.0, -1.0 / inverse)

    @property
    def precision_solref(self) -> tuple[float, float]:
        """Default: the stiffest stable time constant (MuJoCo clamps timeconst to >= 2 * timestep)."""
        tc = 2.0 * self.timestep if self.precision_timeconst is None else self.precision_timeconst
        return (tc, self.precision_dampratio)

    def apply(self, spec: mujoco.MjSpec) -> None:
        """Write the global options into a scene spec (children's options are ignored on attach)."""
        opt = spec.option
        opt.timestep = self.timestep
        opt.iterations = self.iterations
        opt.ls_iterations = self.ls_iterations
        opt.tolerance = self.tolerance
        opt.ccd_tolerance = self.ccd_tolerance
        opt.impratio = self.impratio
        opt.noslip_iterations = self.noslip_iterations
        opt.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        if self.sleep:
            opt.enableflags |= int(mujoco.mjtEnableBit.mjENBL_SLEEP)
            opt.sleep_tolerance = self.sleep_tolerance

    def precision_contact(self, geom: mujoco.MjsGeom) -> None:
        """Mark a geom as part of a micrometre-precision contact pair (journal or bore)."""
        geom.solref = list(self.precision_solref)
        geom.solimp = list(self.precision_solimp)
        geom.friction = [self.precision_friction, 0.005, 0.0001]
        geom.condim = 4
        geom.priority = 1


AWAKE = int(mujoco.mjtSleepState.mjS_AWAKE)
"""data.body_awake of a body whose tree is being integrated (asleep: mjS_ASLEEP, static: mjS_STATIC)."""

WAKE_NUDGE = 1e-30
"""[m/s]: MuJoCo wakes a sleeping tree whose velocity is not exactly zero (mj_wake); this
velocity moves nothing in any run's lifetime."""


def wake_tree_of(data: mujoco.MjData, dof: int) -> None:
    """Wake the sleeping island holding `dof` at the next step: a sleeping tree ignores new
    ctrl. (Writing data.tree_asleep instead breaks MuJoCo's sleep cycles and aborts.)"""
    if data.qvel[dof] == 0.0:
        data.qvel[dof] = WAKE_NUDGE

