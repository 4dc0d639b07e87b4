"""A concealed cell: an assembly episode (``serpar run --record``) of a cell whose physics
differ from the nominal simulator's in one to four drawn effects, recorded with a log that says
what a real cell's would (seed, holes, the part population; tasks/episode_config.py
``cell_log``) and nothing of the physics. The truth goes to ``answer.json`` in ``serpar
diagnose``'s own effect and parameter names, relative to the nominal simulator
(:data:`NOMINAL`: ``EpisodeConfig()``), and to ``answer.model.json``, the arm plant it was run
with; both sit beside the recording, never in it.

| effect | drawn | in the cell | answer (diagnose's names) |
|---|---|---|---|
| joint_friction | 1.5-3x a real Panda's, the published form (Gaz et al. 2019: sigmoid with offset) | the runtime's drive torque (sim/plants/drive_friction.py), replacing the nominal 0.3x dry friction | Fc<j>: the sigmoid's level at speed, Fv<j>: 0; its offset and its passage through zero are outside that form (``outside_form``); the same friction in ``sigmoid_friction``'s names under ``also``: phi1_j, phi2_j, phi3_j |
| sensor_timing | the torque sensors read 0.5-2 ms late | MuJoCo sensor ``delay`` | lag [s] |
| latency | commands act 0.5-2 ms late | MuJoCo actuator ``delay`` | delay [s] |
| payload | 0.05-0.3 kg more hand than the nominal one (a camera, an adapter) | a body on the flange | mass, com_x/y/z |
| contact_friction | journal/bore friction 0.1-0.5 (nominal 0.2) | the cell's precision-contact friction | d_mu = mu - 0.2 |
| stribeck_friction | static friction above the Coulomb level on every joint: Fs - Fc 0.5-1.5x the nominal cell's Coulomb level (0.3x a real Panda's), vs 0.02-0.08 rad/s | the joints' dry friction level rising to Fs at rest (sim/plants/drive_friction.py) | dFs<j>, vs<j> |
| armature | rotor inertia the MJCF lacks on joints 3-7: 0.3-1 x the nominal 0.1 kg m^2, +-50 % per joint | joint ``armature`` | Ia<j> |

``mix`` draws two to four of them: of the first five for seeds below
:data:`EXTENDED_FROM_SEED` (what those seeds always drew, pinned by tests/test_cell_twin.py),
of all seven from it on. The Stewart platform's leg offsets "within the calibrated
residual" are not drawn: the cell's campaign calibrates the platform it runs on, so an offset
it has not seen would have to be added after it, and at the calibrated residual's size (under
1 um) no episode signal carries it.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from serpar.calibration.camera_cache import calibrated_pairs
from serpar.errors import ConfigError
from serpar.sim.arm import (
    GAZ_FRICTION_PHI,
    JOINT_NAMES,
    N_JOINTS,
    PANDA_COULOMB_FRICTION,
    build_arm_spec,
)
from serpar.sim.physics import PhysicsConfig
from serpar.sim.plants.drive_friction import gaz_levels, gaz_sigmoid_params
from serpar.sim.strict_json import dumps
from serpar.tasks.episode import HoleRecord, run_episode
from serpar.tasks.episode_config import N_HOLES, EpisodeConfig
from serpar.tasks.run_episodes import recording_folder
from serpar.twins.arm_twin_scale import ROTOR_JOINTS

MIX_BEFORE_SEED_20: tuple[str, ...] = ("joint_friction", "sensor_timing", "latency", "payload",
                                       "contact_friction")
EFFECTS: tuple[str, ...] = MIX_BEFORE_SEED_20 + ("stribeck_friction", "armature")
EXTENDED_FROM_SEED = 20
"""``mix`` draws from every effect from this seed on; below it from :data:`MIX_BEFORE_SEED_20`,
so the cells measured in docs/ draw what they always drew."""
STRIBECK_SPEED = (0.02, 0.08)  # [rad/s], as the arm-dynamics twin's
ROTOR_SCATTER = 0.5  # +-50 % per joint
RANGES: dict[str, tuple[float, float]] = {
    "joint_friction": (1.5, 3.0),
    "sensor_timing": (0.0005, 0.002),
    "latency": (0.0005, 0.002),
    "payload": (0.05, 0.3),
    "contact_friction": (0.1, 0.5),
    "stribeck_friction": (0.5, 1.5),
    "armature": (0.3, 1.0),
}
NOMINAL = EpisodeConfig()
"""The nominal simulator a concealed cell differs from."""
NOMINAL_MU = PhysicsConfig().precision_friction
PLANT_FILE = "answer.model.json"
ANSWER_FILE = "answer.json"


def check_effect(effect: str) -> None:
    """ConfigError naming the valid choices unless ``effect`` is mix, none or a cell effect."""
    if effect not in ("mix", "none", *EFFECTS):
        raise ConfigError(f"unknown cell effect {effect!r}; valid: mix, none, {', '.join(EFFECTS)}")


def draw_effects(effect: str, rng: np.random.Generator, seed: int = 0) -> tuple[str, ...]:
    """The effects of a twin: ``mix`` (two to four, from the pool of its seed), one name, or
    ``none``."""
    check_effect(effect)
    if effect == "mix":
        pool = EFFECTS if seed >= EXTENDED_FROM_SEED else MIX_BEFORE_SEED_20
        k = int(rng.integers(2, 5))
        return tuple(sorted((str(e) for e in rng.choice(pool, size=k, replace=False)),
                            key=EFFECTS.index))
    return () if effect == "none" else (effect,)


def _block(params: dict[str, float]) -> dict[str, list]:
    return {"names": list(params), "values": list(params.values()), "std": [0.0] * len(params)}


def _payload(rng: np.random.Generator) -> dict[str, float]:
    mass = float(rng.uniform(*RANGES["payload"]))
    com = (rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02), rng.uniform(0.03, 0.08))
    side = 0.04 / np.sqrt(3.0)  # a solid 8 cm cube's extent
    return {"mass": mass, "com_x": float(com[0]), "com_y": float(com[1]), "com_z": float(com[2]),
            "Lxx": side, "Lyx": 0.0, "Lyy": side, "Lzx": 0.0, "Lzy": 0.0, "Lzz": side}


def _stribeck(rng: np.random.Generator) -> dict[str, float]:
    """Fs - Fc on every joint, relative to the nominal cell's Coulomb level (Fs / Fc 1.5-2.5,
    the arm-dynamics twin's), and each joint's vs (log-uniform)."""
    ratio = rng.uniform(*RANGES["stribeck_friction"], N_JOINTS)
    speed = np.exp(rng.uniform(*np.log(STRIBECK_SPEED), N_JOINTS))
    level = NOMINAL.arm_friction * np.asarray(PANDA_COULOMB_FRICTION)
    return {**{f"dFs{j + 1}": float(r * c) for j, (r, c) in enumerate(zip(ratio, level))},
            **{f"vs{j + 1}": float(v) for j, v in enumerate(speed)}}


def _rotors(rng: np.random.Generator) -> dict[str, float]:
    """Rotor inertia the MJCF lacks on the Panda's rotor joints (twins/arm_twin_scale.py's
    ROTOR_JOINTS: joint 1's and 2's are grouped with the links' inertia, no data name them)."""
    mag = rng.uniform(*RANGES["armature"])
    nominal = build_arm_spec()
    return {f"Ia{j}": (float(mag * nominal.joint(n).armature
                             * rng.uniform(1 - ROTOR_SCATTER, 1 + ROTOR_SCATTER))
                       if j in ROTOR_JOINTS else 0.0) for j, n in enumerate(JOINT_NAMES, 1)}


def concealed_cell(effect: str, seed: int, holes: int
                   ) -> tuple[dict[str, object], dict[str, object], dict[str, object] | None]:
    """The concealed cell: its changes to the nominal episode config, its answer, and its arm
    plant as a model file (None when no drawn effect is the arm's plant)."""
    if not 1 <= holes <= N_HOLES:
        raise ConfigError(f"--holes {holes}: valid 1..{N_HOLES}")
    rng = np.random.default_rng([seed, 30])
    drawn = draw_effects(effect, rng, seed)
    changes: dict[str, object] = {}
    answers: list[dict[str, object]] = []
    plant: dict[str, dict[str, list]] = {}
    for name in drawn:
        if name == "joint_friction":
            scale = float(rng.uniform(*RANGES[name]))
            level, offset = gaz_levels(scale)
            changes.update(arm_friction=scale, arm_friction_form="gaz")
            answers.append({"effect": name, "params": {
                **{f"Fc{j + 1}": float(v) for j, v in enumerate(level)},
                **{f"Fv{j + 1}": 0.0 for j in range(len(level))}},
                "scale_of_a_real_panda": scale,
                "outside_form": {"form": "Gaz et al. 2019 sigmoid with offset",
                                 "offset_nm": [float(v) for v in offset],
                                 "transition_rad_s": [1.0 / p for p in GAZ_FRICTION_PHI[1]]},
                "also": {"effect": "sigmoid_friction", "params": gaz_sigmoid_params(scale),
                         "replaces": "the nominal cell's dry friction (arm_friction "
                                     f"{NOMINAL.arm_friction} x a Panda's Coulomb level)"}})
        elif name in ("sensor_timing", "latency"):
            value = float(rng.uniform(*RANGES[name]))
            params = {"lag" if name == "sensor_timing" else "delay": value}
            plant[name] = _block(params)
            answers.append({"effect": name, "params": params})
        elif name == "payload":
            params = _payload(rng)
            plant[name] = _block(params)
            answers.append({"effect": name, "params": {k: params[k] for k in
                                                       ("mass", "com_x", "com_y", "com_z")}})
        elif name in ("stribeck_friction", "armature"):
            params = _stribeck(rng) if name == "stribeck_friction" else _rotors(rng)
            plant[name] = _block(params)
            answers.append({"effect": name, "params": params})
        else:  # contact_friction
            mu = float(rng.uniform(*RANGES[name]))
            changes["contact_friction"] = mu
            answers.append({"effect": name, "params": {"d_mu": mu - NOMINAL_MU}, "mu": mu})
    model = ({"source": "serpar twin --domain cell (the concealed truth)", "kind": "arm_dynamics",
              "effects": list(plant), "params": plant} if plant else None)
    answer: dict[str, object] = {
        "domain": "cell", "effect": effect, "effects": answers, "seed": seed, "holes": holes,
        "nominal": "EpisodeConfig() defaults: arm_friction 0.3 (coulomb), contact_friction "
                   f"{NOMINAL_MU}, no delays, no payload",
        "concealed_config": {k: changes.get(k, getattr(NOMINAL, k)) for k in
                             ("arm_friction", "arm_friction_form", "contact_friction")}}
    return changes, answer, model


def make_cell_twin(effect: str, seed: int, holes: int, out: str | Path,
                   on_hole: Callable[[HoleRecord], None] | None = None) -> dict[str, object]:
    """Run and record the concealed cell into ``out`` (``episode_<seed>/``, ``answer.json``,
    ``answer.model.json``); returns the answer."""
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    changes, answer, model = concealed_cell(effect, seed, holes)
    if model is not None:
        (root / PLANT_FILE).write_text(json.dumps(model, indent=2))
        changes["plant_model"] = str(root / PLANT_FILE)
    cfg = dataclasses.replace(NOMINAL, seed=seed, holes=holes, **changes)  # type: ignore[arg-type]
    folder = recording_folder(root, seed)
    summary = run_episode(cfg, calibrated_pairs(cfg.camera_width), on_record=on_hole,
                          recording=folder, concealed=True)
    answer = {**answer, "recording": str(folder), "successes": summary.successes,
              "counts": summary.counts}
    (root / ANSWER_FILE).write_text(dumps(answer, indent=2))
    return answer
