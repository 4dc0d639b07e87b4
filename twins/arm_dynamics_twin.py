"""Arm-dynamics twins: a "real" arm (the Panda, or any arm from its URDF/MJCF file:
``arm=``) with one concealed piece of physics the nominal model lacks, recorded like a
libfranka log (q, dq, tau_J, tau_J_d at 1 kHz), for ``serpar twin`` / ``serpar blind-bench``
and the tests of the time-series diagnosis.

The reality is built from MuJoCo's own physics wherever MuJoCo can express the effect
(``frictionloss`` + ``damping`` for joint friction, an added body for a payload, scaled body
inertias for a link error); sensor and drive effects (torque-sensor gain and bias, encoder
offset, actuation latency, torque-sensor timing, a coupled motor) act on the signals in
sim/plants/moving_arm.py (twins/arm_twin_physics.py, twins/arm_twin_signals.py). The answer
goes into the returned dict, never into the recording.

On another arm than the Panda the magnitudes below are the Panda's: those in absolute units
(friction, ripple, sensor offsets, payload mass, rotor inertia) are scaled to the arm, and the
joints and links the Panda's lists name are computed from its model (the rules:
twins/arm_twin_scale.py).

Magnitude per effect (drawn from the range in :data:`MAGNITUDE_RANGE` when not given):

| effect | magnitude | what else is drawn |
|---|---|---|
| joint_friction | multiple of a real Panda's friction (Gaz et al. 2019 Coulomb levels, viscous ~0.1-0.2 N m s/rad) | per-joint spread ±30 %; dry friction sticks at reversals |
| payload | mass [kg] | CoM: x, y within ±4 cm of the flange axis, z 2-10 cm out; a solid box |
| link_inertia | relative mass error of one link (inertia tensor scaled with it) | which link (3, 4 or 5), the sign |
| torque_sensor | largest gain error (0.03 = +3 %) | per-joint gains 50-100 % of it, one sign for all (a payload fit mimics it on tau_J), offsets ±0.1-0.5 N m |
| latency | actuation delay [s] | — (0.1 ms resolution) |
| sensor_timing | how late the torque sensors read against the encoders [s] | — (0.1 ms resolution; the simulated cell's own sensors read half a substep late, ~0.05 ms) |
| encoder_offset | largest offset [rad] | offsets of joints 2-6 (joint 1's is invisible to dynamics: gravity is along its axis) |
| link_friction | multiple of a real Panda's friction, as joint_friction | the same Coulomb + viscous friction, acting between the torque sensor and the link (bearings, seals): the sensor reads it, in tau_J as in tau_J_d |
| stribeck_friction | multiple of a real Panda's friction, as joint_friction | joint_friction's Coulomb + viscous, plus a Stribeck excess (Fs - Fc) exp(-(v/vs)^2) against the motion: Fs/Fc 1.5-2.5, vs 0.02-0.08 rad/s per joint |
| sigmoid_friction | multiple of a real Panda's friction (Gaz et al. 2019's phi1) | per joint phi1 ±30 %, phi2 the Panda's along the chain ±30 %, phi3 within ±0.05 rad/s: the drive loses phi1 (sigma(phi2 (dq + phi3)) - sigma(phi2 phi3)), no Coulomb or viscous friction beside it |
| base_tilt | tilt of the base [rad] | its direction (uniform): gravity in the base frame turned by alpha = mag cos(az), beta = mag sin(az) |
| torque_ripple | amplitude A [N m] of A sin(2 pi q_j / P + phi) in one drive | the joint (2-6), the period P (10-45 deg), the phase |
| encoder_scale | largest relative scale error abs(s) (encoder reads q (1 + s) about its zero, dq too) | its joint (2-4), the sign; half the time a second, smaller one on another joint of 2-6 |
| armature | multiple of the joint's rotor inertia (the file's armature; where it has none, half the joint's mean inertia) | per joint 50-150 % of it, on the joints whose rotor the links' inertias do not take (the Panda's 3-7) |
| coupled_pair | multiple of a coupled motor's Iam, fvm, fsm (Iam: 0.2 x joint n-1's rotor inertia; fvm, fsm: joint n's friction, on joint n-1's drive) | per parameter 70-130 %; the motor of joint n also turns joint n-1 (the TX40's wrist): each of the two drives carries Iam and fvm in the other joint's motion and fsm sign(dq_n-1 + dq_n) (FIGAROH's structure, as the diagnosis' coupled_pair), in tau_J_d, not in tau_J; the recording declares ``couplings`` [[n-1, n]] |

The torque ripple (:data:`OUT_OF_LIBRARY`) has no candidate in the diagnosis library: it should
come out as a structured residual that no library effect explains, characterised as an
empirical term. Stribeck friction, encoder scale and the sigmoid friction have candidates; the blind bench also
draws them with their candidate withheld (:data:`WITHHELD`), as physics outside the library.
The answers of these four carry a ``signature``: the channels the residual shows in, the
variables it follows, in words.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields, replace

import mujoco
import numpy as np
import pyarrow as pa

from serpar.errors import ConfigError
from serpar.sim import channels as ch
from serpar.sim.plants.arm_plant import plant_spec
from serpar.sim.plants.arm_reality import Reality, SensorNoise
from serpar.sim.plants.moving_arm import TwinRun, simulate
from serpar.sim.recording import PhaseSegment, Recording, RecordingMeta
from serpar.sim.rigid_arm import PANDA_ARM, ArmModel
from serpar.twins import arm_twin_physics as physics
from serpar.twins import arm_twin_signals as signals
from serpar.twins.arm_twin_physics import plant_model as _plant
from serpar.twins.arm_twin_scale import ArmScale, arm_scale

OUT_OF_LIBRARY: tuple[str, ...] = ("torque_ripple",)
"""Effects the diagnosis has no candidate for: they must come out as unexplained residual."""
WITHHELD: tuple[str, ...] = ("stribeck_friction", "encoder_scale", "sigmoid_friction")
"""Library effects the blind bench also draws with their candidate withheld from the
diagnosis: physics outside the library, with a signature to score the empirical term by."""
PARTLY_IN_LIBRARY: dict[str, tuple[str, ...]] = {
    "stribeck_friction": ("joint_friction",),
    "encoder_scale": ("encoder_offset",),
    "sigmoid_friction": ("joint_friction",),
}
"""Library effects that express part of an effect's physics (not a wrong finding when
established with it, or for it while its candidate is withheld): Stribeck friction's Coulomb
and viscous levels; a scale error's mean over the joint's travel, a constant offset; the
sigmoid's level at speed (a Coulomb friction)."""
DECLARED: tuple[str, ...] = ("coupled_pair",)
"""Library effects the diagnosis offers only where the recording declares them: a coupled
drive (its twin writes ``meta.model["couplings"]``)."""
EFFECTS: tuple[str, ...] = ("joint_friction", "link_friction", "payload", "link_inertia",
                            "torque_sensor", "latency", "sensor_timing", "encoder_offset",
                            "stribeck_friction", "encoder_scale", "armature", "coupled_pair",
                            "sigmoid_friction", "base_tilt", *OUT_OF_LIBRARY)
MAGNITUDE_RANGE: dict[str, tuple[float, float]] = {
    "joint_friction": (0.2, 1.0),
    "link_friction": (0.2, 1.0),
    "payload": (0.2, 1.5),
    "link_inertia": (0.1, 0.3),
    "torque_sensor": (0.02, 0.06),
    "latency": (0.001, 0.004),
    "sensor_timing": (0.0005, 0.002),
    "encoder_offset": (0.001, 0.004),
    "stribeck_friction": (0.5, 1.0),
    "torque_ripple": (0.15, 0.6),
    "encoder_scale": (0.005, 0.015),
    "armature": (0.3, 1.0),
    "coupled_pair": (0.5, 1.5),
    "sigmoid_friction": (0.5, 1.5),
    "base_tilt": (0.003, 0.015),
}
MIX = "mix"
MIX_FRICTION: tuple[str, ...] = ("joint_friction", "sigmoid_friction")
MIX_POOL: tuple[str, ...] = ("payload", "link_inertia", "base_tilt", "armature", "latency",
                             "encoder_offset")
"""``mix``: one friction form and two of these, each at a magnitude drawn from its range."""
DURATION = 20.0
DURATION_RANGE = (5.0, 120.0)
RATE = 1000.0


def make_twin(effect: str | None, magnitude: float | None, seed: int,
              duration: float = DURATION, noise: SensorNoise | None = None,
              arm: ArmModel = PANDA_ARM) -> tuple[Recording, dict[str, object]]:
    """A recording of a "real" ``arm`` with `effect` (None: the nominal arm), and the answer."""
    noise = noise or SensorNoise()
    if effect is not None and effect not in (*EFFECTS, MIX):
        raise ConfigError(f"unknown effect {effect!r}; valid: {', '.join(EFFECTS)}, {MIX} "
                          "(or none)")
    lo, hi = DURATION_RANGE
    if not lo <= duration <= hi:
        raise ConfigError(f"duration {duration} s outside {lo:g}..{hi:g} s")
    if arm.n < 2 and effect == "coupled_pair":
        raise ConfigError(f"coupled_pair needs two joints; {arm.name} has {arm.n}")
    effect_rng, sim_seed = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(2))
    if effect == MIX and magnitude is not None:
        raise ConfigError("--magnitude is per effect; mix draws each of its effects' own")
    if effect is not None and effect != MIX and magnitude is None:
        magnitude = float(effect_rng.uniform(*MAGNITUDE_RANGE[effect]))
    if magnitude is not None and not (np.isfinite(magnitude) and magnitude > 0):
        raise ConfigError(f"magnitude {magnitude} must be a positive number")
    scale = arm_scale(arm)
    spec = plant_spec(arm)
    reality = Reality(n=arm.n)
    signature: dict[str, object] | None = None
    couplings: list[list[int]] = []
    parts: list[dict[str, object]] = []
    for name in (_mix_draw(effect_rng) if effect == MIX else (effect,) if effect else ()):
        size = (float(effect_rng.uniform(*MAGNITUDE_RANGE[name])) if effect == MIX
                else magnitude)
        part, params, sig, coupled = _apply(name, spec, size, effect_rng, scale)
        reality = _merged(reality, part)
        signature, couplings = sig or signature, coupled or couplings
        parts.append({"effect": name, "magnitude": size, "params": params})
    params = {k: v for p in parts for k, v in p["params"].items()}  # type: ignore[attr-defined]
    run = simulate(_plant(spec), reality, noise, duration, RATE,
                   int(sim_seed.integers(2**31)), arm=arm)
    if effect == "encoder_scale":
        signature = signals.scale_signature(reality, run, RATE, scale)
    elif effect in ("stribeck_friction", "sigmoid_friction"):
        signature = signals.friction_signature(effect, reality, run, RATE)
    answer: dict[str, object] = {"effect": effect, "magnitude": magnitude, "params": params,
                                 **({"effects": parts} if effect == MIX else {}),
                                 "torque_offset": [float(b) for b in run.torque_offset],
                                 "saturated_samples": run.saturated}
    if not arm.is_panda:
        answer["robot"] = arm.source
    if signature is not None:
        answer["signature"] = signature
    return _recording(run, noise, arm, couplings), answer


def _apply(effect: str, spec: mujoco.MjSpec, magnitude: float | None, rng: np.random.Generator,
           scale: ArmScale) -> tuple[Reality, Mapping[str, object], dict[str, object] | None,
                                     list[list[int]]]:
    """One effect on the plant's spec and signals: (its Reality, its parameters, its
    signature, the couplings it declares)."""
    n = scale.n
    reality, signature, couplings = Reality(n=n), None, []
    params: Mapping[str, object]
    if effect == "joint_friction":
        params = physics.friction(spec, magnitude, rng, scale)
    elif effect == "link_friction":
        params = physics.friction(spec, magnitude, rng, scale)
        viscous = np.array([params[f"Fv{j + 1}"] for j in range(n)])
        reality = Reality(link_side_friction=True, link_side_viscous=viscous, n=n)
    elif effect == "stribeck_friction":
        reality, params = signals.stribeck(spec, magnitude, rng, scale)
    elif effect == "sigmoid_friction":
        reality, params = signals.sigmoid(magnitude, rng, scale)
    elif effect == "torque_ripple":
        reality, params, signature = signals.ripple(magnitude, rng, scale)
    elif effect == "encoder_scale":
        reality, params = signals.encoder_scale(magnitude, rng, scale)
    elif effect == "coupled_pair":
        reality, params, couplings = signals.coupled_pair(spec, magnitude, rng, scale)
    elif effect == "payload":
        params = physics.payload(spec, magnitude, rng, scale)
    elif effect == "link_inertia":
        params = physics.link_inertia(spec, magnitude, rng, scale)
    elif effect == "armature":
        params = physics.armature(spec, magnitude, rng, scale)
    elif effect == "base_tilt":
        params = physics.base_tilt(spec, magnitude, rng, scale)
    else:
        reality, params = signals.reality(effect, magnitude, rng, scale)
    return reality, params, signature, couplings


def _mix_draw(rng: np.random.Generator) -> tuple[str, ...]:
    """One friction form and two others of :data:`MIX_POOL`, in EFFECTS order."""
    friction = str(rng.choice(MIX_FRICTION))
    others = [str(e) for e in rng.choice(MIX_POOL, size=2, replace=False)]
    return tuple(sorted([friction, *others], key=EFFECTS.index))


def _merged(a: Reality, b: Reality) -> Reality:
    """``a`` with every field ``b`` sets (differs from an unset Reality's)."""
    unset = Reality(n=a.n)
    changed = {f.name: getattr(b, f.name) for f in fields(Reality)
               if not _same(getattr(b, f.name), getattr(unset, f.name))}
    return replace(a, **changed) if changed else a


def _same(x: object, y: object) -> bool:
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        return x is not None and y is not None and np.array_equal(x, y)
    return x == y


def _recording(run: TwinRun, noise: SensorNoise, arm: ArmModel,
               couplings: list[list[int]]) -> Recording:
    cols = {ch.TIME: run.time}
    sigma = {}
    n = arm.n
    for prefix, x, std in (("q", run.q, noise.encoder_sigma), ("dq", run.dq, noise.velocity_std),
                           ("tau_J", run.tau_J, noise.torque_std),
                           ("tau_J_d", run.tau_J_d, noise.actuation_std)):
        names = tuple(f"{prefix}{j + 1}" for j in range(n))
        cols.update({c: x[:, j] for j, c in enumerate(names)})
        sigma.update({c: std for c in names})
    model: dict[str, object] = {
        "arm": ("assets/arm/panda.xml, hand rigid and closed" if arm.is_panda
                else f"{arm.source} ({arm.name}, {n} joints)"),
        "controller": ("joint PD (libfranka example gains) + nominal feedforward, 1 kHz"
                       if arm.is_panda else
                       "joint PD (gains scaled to the arm's inertia, sim/plants/arm_plant.py) "
                       "+ nominal feedforward, 1 kHz"),
        "notes": {"q": "encoder reading at the row's time",
                  "tau_J": "link-side torque, mean over the control period ending at the row's time",
                  "tau_J_d": "command held over the period starting at the row's time; "
                             "noise_sigma = the drive's torque ripple about it"}}
    if not arm.is_panda:  # the Panda's recordings stay as they were (no "robot": the default)
        model["robot"] = arm.source
    if couplings:
        model["couplings"] = couplings
    meta = RecordingMeta(
        source="sim", sample_rate_hz=RATE, channels=tuple(cols), noise_sigma=sigma,
        phases=(PhaseSegment("excitation", 0.0, float(run.time[-1])),), model=model)
    return Recording(meta, pa.table(cols))


__all__ = ["DECLARED", "DURATION", "EFFECTS", "MAGNITUDE_RANGE", "MIX", "OUT_OF_LIBRARY",
           "PARTLY_IN_LIBRARY", "RATE", "WITHHELD", "_plant", "make_twin"]
