"""Property-based fuzzing of the model-file reader (`plant_model:`, `--model`): a damaged
<stem>.model.json ends in a plant or a one-line ConfigError, never a traceback; a plant that is
built carries only finite numbers."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from serpar.errors import ConfigError
from serpar.sim.plants.from_model_file import arm_plant_from_file

DATA = Path(__file__).parent / "data"
GOOD = json.loads((DATA / "payload_twin.model.json").read_text())
FUZZ = settings(max_examples=150, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

leaves = st.one_of(st.none(), st.booleans(), st.integers(-3, 3), st.floats(), st.text(max_size=8),
                   st.sampled_from(["payload", "joint_friction", "mass", "Fc1", "latency"]))
values = st.recursive(leaves, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                      st.dictionaries(st.text(max_size=6), inner, max_size=3)),
                      max_leaves=10)


def _paths(obj: object, prefix: tuple = ()) -> list[tuple]:
    out = [prefix]
    if isinstance(obj, dict):
        for k, v in obj.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out += _paths(v, (*prefix, i))
    return out


PATHS = [p for p in _paths(GOOD) if p]


def _finite(obj: object) -> bool:
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, (list, tuple)):
        return all(_finite(v) for v in obj)
    if isinstance(obj, dict):
        return all(_finite(v) for v in obj.values())
    return True


@FUZZ
@given(where=st.sampled_from(PATHS), value=values)
def test_damaged_model_file(tmp_path: Path, where: tuple, value: object) -> None:
    data = copy.deepcopy(GOOD)
    node = data
    for key in where[:-1]:
        node = node[key]
    node[where[-1]] = value
    path = tmp_path / "m.model.json"
    path.write_text(json.dumps(data))
    try:
        plant = arm_plant_from_file(path)
    except ConfigError as exc:
        assert str(exc) and "\n" not in str(exc), str(exc)
        return
    assert _finite([plant.frictionloss, plant.damping, plant.joint_ref, plant.link_mass_scale,
                    plant.actuation_delay])


@FUZZ
@given(text=st.text(max_size=60))
def test_any_text_as_model_file(tmp_path: Path, text: str) -> None:
    path = tmp_path / "m.model.json"
    path.write_text(text)
    try:
        arm_plant_from_file(path)
    except ConfigError as exc:
        assert str(exc) and "\n" not in str(exc), str(exc)
