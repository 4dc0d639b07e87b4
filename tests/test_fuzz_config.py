"""Property-based fuzzing of the config loader (YAML at the command-line edge): any input ends
in a config or a one-line ConfigError, never a traceback, and an accepted config holds every
given value with its field's type (a string is never a boolean, a float never a hole list)."""

from __future__ import annotations

import dataclasses
import typing

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from serpar.errors import ConfigError
from serpar.sim.config_io import from_dict, load_yaml_config
from serpar.sim.physics import PhysicsConfig
from serpar.sim.scene import SceneConfig
from serpar.tasks.episode_config import EpisodeConfig

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])

scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True),
                    st.text(max_size=12), st.sampled_from(["true", "false", "nope", "table5", "1e300",
                                                           "high", "3.5", "-1", ""]))
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                       st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                      max_leaves=12)


def _mappings(cls: type) -> st.SearchStrategy[dict]:
    keys = [f.name for f in dataclasses.fields(cls)] + ["not_a_key"]
    return st.dictionaries(st.sampled_from(keys), values, max_size=4)


def _holds(hint: object, value: object) -> bool:
    """Whether a built config's field value is of the annotated type (recursively)."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return isinstance(value, float)
    if hint is str:
        return isinstance(value, str)
    if hint is type(None):
        return value is None
    if origin in (typing.Union, __import__("types").UnionType):
        return any(_holds(a, value) for a in args)
    if origin is tuple:
        if not isinstance(value, tuple):
            return False
        members = [args[0]] * len(value) if len(args) == 2 and args[1] is Ellipsis else list(args)
        return len(members) == len(value) and all(_holds(a, v) for a, v in zip(members, value))
    return True  # nested dataclasses and library types: checked by their own construction


def _check(cls: type, given_values: dict) -> None:
    try:
        cfg = from_dict(cls, given_values, "fuzz.yaml")
    except ConfigError as exc:
        message = str(exc)
        assert message and "\n" not in message, message
        return
    hints = typing.get_type_hints(cls)
    for name, value in given_values.items():  # nothing given is dropped; each has its field's type
        assert _holds(hints[name], getattr(cfg, name)), (name, value, getattr(cfg, name))


@FUZZ
@given(_mappings(EpisodeConfig))
def test_episode_config_result_or_one_line_error(given_values: dict) -> None:
    _check(EpisodeConfig, given_values)


@FUZZ
@given(_mappings(PhysicsConfig))
def test_physics_config_result_or_one_line_error(given_values: dict) -> None:
    _check(PhysicsConfig, given_values)


@settings(max_examples=60, deadline=None)
@given(st.dictionaries(st.sampled_from(["seed", "n_conductors", "tolerance_distribution", "baseplate",
                                        "stewart_base", "tray_height", "physics"]), values, max_size=3))
def test_scene_config_result_or_one_line_error(given_values: dict) -> None:
    _check(SceneConfig, given_values)


@FUZZ
@given(st.text(max_size=80))
def test_any_yaml_text_loads_or_fails_in_one_line(tmp_path_factory: pytest.TempPathFactory, text: str) -> None:
    path = tmp_path_factory.mktemp("cfg") / "run.yaml"
    path.write_text(text)
    try:
        load_yaml_config(EpisodeConfig, path)
    except ConfigError as exc:
        assert str(exc) and "\n" not in str(exc)


@pytest.mark.parametrize(("text", "expected"), [
    ('sensor_noise: "false"', "sensor_noise: expected true or false, got 'false' (a string)"),
    ("stewart_correction: nope", "stewart_correction: expected true or false"),
    ("hidden_errors: table5", "hidden_errors: expected a mapping with keys mode, scale"),
    ("holes: 3.5", "holes: expected a list of integers or an integer, got 3.5"),
    ("holes: [1, 2.5]", "holes[1]: expected an integer, got 2.5"),
    ("arm_friction: high", "arm_friction: expected a number, got 'high'"),
    ("arm_friction: .nan", "arm_friction: expected a finite number"),
    ("seed: -1", "seed must be a non-negative integer, got -1"),
    ("seed: true", "seed: expected an integer, got True (a boolean)"),
    ("holes: [1, 2", "not valid YAML at line 2, column 1"),
])
def test_bad_values_named_in_one_line(tmp_path, text: str, expected: str) -> None:
    path = tmp_path / "run.yaml"
    path.write_text(text + "\n")
    with pytest.raises(ConfigError) as err:
        load_yaml_config(EpisodeConfig, path)
    assert expected in str(err.value) and str(err.value).startswith(("run.yaml", "config file"))


def test_chamfer_message_in_one_unit_system(tmp_path) -> None:
    path = tmp_path / "scene.yaml"
    path.write_text("baseplate: {chamfer: 0.1}\n")
    with pytest.raises(ConfigError, match=r"chamfer 0.1 m \(100 mm\) outside 0..0.0005 m \(0..0.5 mm\)"):
        load_yaml_config(SceneConfig, path)


def test_accepted_values_keep_their_meaning(tmp_path) -> None:
    path = tmp_path / "run.yaml"
    path.write_text(yaml.safe_dump({"sensor_noise": False, "holes": [3, 5], "arm_friction": 1,
                                    "hidden_errors": {"mode": "none"}}))
    cfg = load_yaml_config(EpisodeConfig, path)
    assert cfg.sensor_noise is False and cfg.holes == (3, 5) and cfg.arm_friction == 1.0
    assert cfg.hidden_errors.mode == "none"
