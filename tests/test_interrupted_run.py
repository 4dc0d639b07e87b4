"""An interrupted or crashed run keeps and reports what finished (issue 26 A): strict JSON,
partial episodes marked, where it stopped, meta.json updated per hole, a worker that dies or
an episode that raises does not end the run."""

from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import serpar.tasks.run_episodes as runner
from serpar.cli.output import json_line
from serpar.sim.recording import read_recording
from serpar.tasks import local_pool
from serpar.tasks.episode import EpisodeInterrupted, EpisodeSummary, build_runtime
from serpar.tasks.episode_config import EpisodeConfig
from serpar.tasks.episode_recorder import EpisodeRecorder
from serpar.tasks.run_episodes import run_many, summarise


def strict(text: str) -> dict:
    def refuse(constant: str) -> None:
        raise ValueError(f"not strict JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


@dataclasses.dataclass
class FakeHole:
    cycle: int
    seed: int

    def as_dict(self) -> dict:
        return {"kind": "hole", "episode_seed": self.seed, "cycle": self.cycle, "hole": self.cycle,
                "outcome": "success", "sim_fault": False, "cycle_time_s": 8.0, "peak_force_n": 4.7,
                "lateral_misalignment_mm": float("nan")}


def hole(seed: int, cycle: int = 0) -> dict:
    return FakeHole(cycle, seed).as_dict()


@pytest.fixture
def fake_episodes(monkeypatch):
    """run_one's real body around a fake episode: seed 0 finishes one hole and is interrupted
    in cycle 1, seed 2 finishes one hole and raises, other seeds fill two holes."""
    def episode(cfg, pairs, on_record=None, recording=None):
        on_record(FakeHole(0, cfg.seed))
        if cfg.seed == 0:
            where = {"signal": "SIGINT", "episode": 0, "cycle": 1, "hole": 5, "phase": "grasp"}
            raise EpisodeInterrupted(where, EpisodeSummary(0, 1, 1, {"success": 1}, 20.0, 30.0, complete=False))
        if cfg.seed == 2:
            raise ValueError("injected")
        on_record(FakeHole(1, cfg.seed))
        return EpisodeSummary(cfg.seed, 2, 2, {"success": 2}, 20.0, 30.0)

    monkeypatch.setattr(runner, "run_episode", episode)
    monkeypatch.setattr(runner, "calibrated_pairs", lambda width: {})
    monkeypatch.setattr(runner, "prepare_models", lambda configs: None)


def test_an_interrupted_episode_keeps_its_finished_holes(fake_episodes):
    streamed: list[list[dict]] = []
    records = run_many([EpisodeConfig(seed=s) for s in (3, 0, 1)], on_records=streamed.append)
    assert [r["kind"] for r in records] == ["hole", "hole", "episode", "hole", "episode", "interrupted"]
    assert records[4]["complete"] is False and records[4]["holes"] == 1
    stop = records[-1]
    assert (stop["signal"], stop["episode"], stop["cycle"], stop["hole"], stop["phase"]) == ("SIGINT", 0, 1, 5, "grasp")
    assert stop["episodes_done"] == 1 and stop["episodes_not_started"] == 1  # seed 1 never ran
    assert all(r["kind"] != "interrupted" for batch in streamed for r in batch)  # folded into the run's record
    summary = summarise(records)
    assert (summary.episodes, summary.partial_episodes, summary.holes) == (2, 1, 3)
    line = strict(json_line(summary.as_dict()))
    assert line["interrupted"]["signal"] == "SIGINT" and line["interrupted"]["stopped"][0]["hole"] == 5


def test_an_episode_that_raises_keeps_its_holes_and_the_run_goes_on(fake_episodes):
    records = run_many([EpisodeConfig(seed=s) for s in (2, 3)])
    assert [r["kind"] for r in records] == ["hole", "error", "hole", "hole", "episode"]
    assert records[1]["episode_seed"] == 2 and "ValueError: injected" in records[1]["error"]
    summary = summarise(records)
    assert (summary.episodes, summary.errors, summary.holes, summary.interrupted) == (1, 1, 3, None)


def test_the_json_of_a_run_without_holes_is_strict():
    line = json_line(summarise([]).as_dict())
    doc = strict(line)
    assert doc["success_rate"] is None and doc["wilson95"] == [None, None] and doc["cycle_time_s"]["mean"] is None
    assert strict(json_line(hole(0)))["lateral_misalignment_mm"] is None


def dying_job(cfg, on_hole=None, label=None):
    """In a worker: seed 1 kills its process (as the OOM killer would), the others take a while."""
    if cfg.seed == 1:
        time.sleep(0.3)
        os._exit(3)
    time.sleep(1.0)
    return [hole(cfg.seed), {"kind": "episode", "seed": cfg.seed, "holes": 1, "complete": True}]


def test_a_worker_that_dies_costs_its_episode_only():
    records = run_many([EpisodeConfig(seed=s) for s in range(4)], workers=2, job=dying_job)
    errors = [r for r in records if r["kind"] == "error"]
    assert [e["episode_seed"] for e in errors] == [1] and "worker process died" in errors[0]["error"]
    assert sorted(r["seed"] for r in records if r["kind"] == "episode") == [0, 2, 3]


def stoppable_job(cfg, on_hole=None, label=None):
    """In a worker: seed 0 ends after 3 s; seed 1 runs until interrupted, then returns what
    run_one returns for an interrupted episode."""
    if cfg.seed == 0:
        time.sleep(3.0)
        return [hole(0), {"kind": "episode", "seed": 0, "holes": 1, "complete": True}]
    try:
        time.sleep(60.0)
    except KeyboardInterrupt as exc:
        return [hole(cfg.seed), {"kind": "episode", "seed": cfg.seed, "holes": 1, "complete": False},
                {"kind": "interrupted", "signal": exc.args[0], "episode": cfg.seed, "cycle": 1, "hole": None,
                 "phase": "locate"}]
    return []


def test_interrupted_workers_close_their_episodes_and_report_them(monkeypatch):
    monkeypatch.setattr(local_pool, "GRACE_S", 30.0)

    seen: list[list[dict]] = []

    def interrupt(records: list[dict]) -> None:  # Ctrl-C once the first episode is in
        seen.append(records)
        if len(seen) == 1:
            raise KeyboardInterrupt

    told: list[str] = []
    t0 = time.perf_counter()
    records = run_many([EpisodeConfig(seed=s) for s in range(4)], workers=2, job=stoppable_job,
                       on_records=interrupt, notify=told.append)
    assert time.perf_counter() - t0 < 30.0
    assert [(r["kind"], r.get("seed", r.get("episode_seed"))) for r in records] == [
        ("hole", 0), ("episode", 0), ("hole", 1), ("episode", 1), ("interrupted", None)]
    stop = records[-1]
    assert stop["signal"] == "SIGINT" and stop["episode"] == 1 and stop["phase"] == "locate"
    assert stop["episodes_done"] == 1 and stop["episodes_not_started"] == 2
    assert told and "closing their episodes" in told[0]
    assert [r["kind"] for r in seen[1]] == ["hole", "episode"]  # the late episode is streamed too


def test_meta_json_tells_complete_and_each_hole_as_it_ends(tmp_path):
    cfg = EpisodeConfig(stewart_calibration="none")
    rt, _ = build_runtime(cfg)
    folder = tmp_path / "episode_0"
    folder.mkdir()
    (folder / "signals.parquet").write_text("a previous recording's")  # replaced (--force)
    recorder = EpisodeRecorder(rt, folder, {"episode_config": dataclasses.asdict(cfg)})
    meta = strict((folder / "meta.json").read_text())
    assert meta["complete"] is False and meta["holes"] == [] and not (folder / "signals.parquet").exists()
    rt.observers.append(recorder)
    rt.run(0.02)
    recorder.hole_done(hole(0))
    meta = strict((folder / "meta.json").read_text())
    assert [h["outcome"] for h in meta["holes"]] == ["success"] and "wall_s" not in meta["holes"][0]
    assert meta["holes"][0]["lateral_misalignment_mm"] is None and meta["phases"][0]["name"] == "start"
    where = {"signal": "SIGINT", "episode": 0, "cycle": 1, "hole": None, "phase": "start"}
    recorder.ended = {"interrupted": where}
    rt.observers.remove(recorder)
    recorder.close()
    meta = strict((folder / "meta.json").read_text())
    assert meta["complete"] is False and meta["ended"] == {"interrupted": where} and len(meta["holes"]) == 1
    assert read_recording(folder).signals.num_rows == 20
    assert sorted(p.name for p in folder.iterdir()) == ["episode.rrd", "meta.json", "signals.parquet"]

    done = EpisodeRecorder(rt, tmp_path / "episode_1", {})
    done.complete = True
    done.close()
    meta = strict((tmp_path / "episode_1" / "meta.json").read_text())
    assert meta["complete"] is True and "ended" not in meta


@pytest.mark.slow
@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["SIGINT", "SIGTERM"])
def test_serpar_run_interrupted_after_its_first_hole(tmp_path, sig, code):
    """The real command, seed 0, 2 holes, signalled once the first hole's line is out. The
    camera and Stewart calibrations come from the shared cache ($SERPAR_CACHE; ~4 min the
    first time, then ~30 s per case)."""
    out = tmp_path / "rec"
    # the child starts as a command typed at a terminal does, SIGINT at its default: a test
    # run started in the background (`pytest ... &`, nohup) ignores SIGINT, an ignored signal
    # survives exec, and Python then installs no KeyboardInterrupt (a background job's
    # convention, which serpar keeps); a handler, unlike SIG_IGN, is reset to the default
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        proc = subprocess.Popen([sys.executable, "-m", "serpar", "run", "--holes", "2", "--record", str(out),
                                 "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    finally:
        signal.signal(signal.SIGINT, previous)
    lines, inherited = [], []
    try:
        for line in proc.stdout:  # type: ignore[union-attr]
            lines.append(line)
            if strict(line)["kind"] == "hole":
                # what the child runs with: an ignored or blocked SIGINT would survive exec
                status = Path(f"/proc/{proc.pid}/status")
                inherited = [s for s in status.read_text().splitlines()
                             if s.startswith(("SigBlk", "SigIgn"))] if status.exists() else []
                proc.send_signal(sig)
                break
        rest, err = proc.communicate(timeout=300)
    finally:
        proc.kill()
    lines += rest.splitlines()
    assert proc.returncode == code, f"{err}\nstdout kinds: {[strict(x)['kind'] for x in lines]}; {inherited}"
    records = [strict(line) for line in lines]
    summary = records[-1]
    assert summary["kind"] == "summary" and summary["holes"] == 1 and summary["episodes"] == 1
    assert summary["partial_episodes"] == 1 and summary["success_rate"] == 1.0
    stop = summary["interrupted"]
    assert stop["signal"] == sig.name and stop["episode"] == 0 and stop["cycle"] == 1 and stop["phase"]
    assert [r["kind"] for r in records] == ["hole", "episode", "summary"] and records[1]["complete"] is False
    assert f"interrupted by {sig.name}" in err and "Traceback" not in err
    meta = strict((out / "episode_0" / "meta.json").read_text())
    assert meta["complete"] is False and meta["ended"]["interrupted"]["cycle"] == 1
    assert [(h["hole"], h["outcome"]) for h in meta["holes"]] == [(0, "success")]
    assert read_recording(Path(out / "episode_0")).signals.num_rows > 10_000  # the recording is readable


def test_first_run_calibrations_report_progress_through_the_callers_stage(monkeypatch, tmp_path, capsys):
    """Long first-run work (issue 26 C): the camera calibration runs inside the caller's
    stage (the command line's prints a line with the elapsed time); a cached pair does not."""
    import contextlib
    from types import SimpleNamespace

    from serpar.calibration import camera_cache
    from serpar.cli.output import stage

    monkeypatch.setenv("SERPAR_CACHE", str(tmp_path))
    camera = SimpleNamespace(as_dict=dict)
    monkeypatch.setattr(camera_cache, "calibrate", lambda *a, **k: SimpleNamespace(
        calibration=SimpleNamespace(pair=SimpleNamespace(left=camera, right=camera)), score={}, views=9))
    seen = []

    @contextlib.contextmanager
    def record(text):
        seen.append(text)
        with stage(text):
            yield

    camera_cache.calibrated_pair("top", 512, stage=record)
    assert len(seen) == 1 and seen[0].startswith("calibrating the top stereo pair at 512 px")
    err = capsys.readouterr().err.splitlines()
    assert err[0].endswith("...") and err[1].startswith("calibrating the top stereo pair at 512 px: done in ")
    monkeypatch.setattr(camera_cache.CameraModel, "from_dict", staticmethod(lambda d: camera))
    camera_cache.calibrated_pair("top", 512, stage=record)  # from the cache now: no stage
    assert len(seen) == 1
