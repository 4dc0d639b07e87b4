"""``--ray``: episodes on a local Ray instance (2 CPUs) give the records of a serial run.

The runner's per-config job is a parameter, so the streaming, labels and ordering are checked
with a cheap deterministic job; the real run_one goes through the same path with configs that
fail fast (a missing Stewart parameter file: an error record, before any camera calibration).
"""

from __future__ import annotations

import functools
import json
import sys
import time

import pytest

from serpar.errors import ConfigError
from serpar.tasks.episode_config import EpisodeConfig
from serpar.tasks.run_episodes import run_many, summarise

pytestmark = [pytest.mark.xdist_group("ray"), pytest.mark.slow]  # one local Ray instance at a time under -n auto


def fake_episode(cfg: EpisodeConfig, on_hole=None, label=None) -> list[dict]:
    """Two holes and a summary, like run_one; later seeds finish first (out of order)."""
    time.sleep(0.05 * (5 - cfg.seed))
    tag = {} if label is None else {"config": label}
    holes = [{"kind": "hole", "episode_seed": cfg.seed, "cycle": k, "outcome": "success" if (cfg.seed + k) % 3
              else "jam", "sim_fault": False, "cycle_time_s": 7.0 + 0.1 * cfg.seed + k,
              "peak_force_n": 5.0 + cfg.seed / 7, **tag} for k in range(2)]
    for h in holes:
        if on_hole:
            on_hole(h)
    return [*holes, {"kind": "episode", "seed": cfg.seed, **tag}]


def _key(r: dict) -> str:
    return json.dumps(r, sort_keys=True)


@pytest.fixture
def ray_2cpu(monkeypatch):
    """The runner's own `ray.init` (address 'local'), held to 2 CPUs; checks it shut Ray down."""
    ray = pytest.importorskip("ray")
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers cannot import tests/
    monkeypatch.setattr(ray, "init", functools.partial(ray.init, num_cpus=2))
    yield ray
    assert not ray.is_initialized()  # what the runner started, it shut down


def test_ray_records_equal_a_serial_run(ray_2cpu):
    configs = [EpisodeConfig(seed=s) for s in range(5)]
    labels = ["serial_alone", "stewart"] * 2 + [None]
    serial = run_many(configs, labels=labels, job=fake_episode)
    streamed: list[list[dict]] = []
    remote = run_many(configs, labels=labels, job=fake_episode, ray_address="local", on_records=streamed.append)
    assert sorted(map(_key, remote)) == sorted(map(_key, serial))
    assert summarise(remote) == summarise(serial)
    assert len(streamed) == 5  # one callback per finished episode, each complete and in order
    for records in streamed:
        assert [r["kind"] for r in records] == ["hole", "hole", "episode"]
        assert [r.get("cycle") for r in records[:2]] == [0, 1]
        assert len({r.get("config") for r in records}) == 1
    assert sum(r.get("config") == "stewart" for r in remote) == 6  # labels travel with the config


def test_ctrl_c_keeps_finished_episodes_and_stops_ray(ray_2cpu):
    def interrupt(records: list[dict]) -> None:
        raise KeyboardInterrupt

    configs = [EpisodeConfig(seed=s) for s in range(4)]
    records = run_many(configs, job=fake_episode, ray_address="local", on_records=interrupt)
    assert [r["kind"] for r in records] == ["hole", "hole", "episode", "interrupted"]
    assert records[-1]["episodes_done"] == 1  # the fixture checks that Ray was shut down


def test_real_run_one_goes_through_ray(ray_2cpu, tmp_path):
    missing = str(tmp_path / "no_such_parameters.json")
    configs = [EpisodeConfig(seed=s, stewart_calibration=missing) for s in (0, 1)]
    serial = run_many(configs)
    remote = run_many(configs, ray_address="local")
    assert [r["kind"] for r in serial] == ["error", "error"] and "no_such_parameters.json" in serial[0]["error"]
    assert sorted(map(_key, remote)) == sorted(map(_key, serial))


def test_ray_choices_are_one_line_errors(monkeypatch):
    from serpar.cli.entry import main
    from serpar.tasks.ray_runner import RAY_MISSING, require_ray

    with pytest.raises(ConfigError, match="choose one"):
        run_many([EpisodeConfig()], workers=2, ray_address="local")
    assert main(["run", "--ray", "local", "--workers", "2"]) == 2
    monkeypatch.setitem(sys.modules, "ray", None)  # as if the cluster extra were not installed
    with pytest.raises(ConfigError) as err:
        require_ray()
    assert str(err.value) == RAY_MISSING == "--ray needs the cluster extra: pip install 'serpar[cluster]'"
    assert main(["ablate", "--ray", "auto"]) == 2


def test_an_unreachable_ray_address_fails_at_once_in_one_line():
    import socket

    from serpar.tasks.ray_runner import check_reachable

    with socket.socket() as s:  # a port nothing listens on: bound, never listening
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        with pytest.raises(ConfigError, match=f"nothing answers at 127.0.0.1:{port}"):
            check_reachable(f"ray://127.0.0.1:{port}")
    with pytest.raises(ConfigError, match="valid: local, auto"):
        check_reachable("ray://nohostport")
    check_reachable("local")
    check_reachable("auto")
    with socket.socket() as s:  # something listening: passes
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        check_reachable(f"127.0.0.1:{s.getsockname()[1]}")
