"""Many episodes: seeds -> records, in this process, in worker processes or on Ray
(:mod:`serpar.tasks.ray_runner`), and the summary.

Each episode depends only on its config (seed included), so a run with W workers gives the
same records as a serial run. Records stream to a callback as they arrive (JSON lines on
the command line); an interrupted run keeps every episode that finished. An episode that
raises is reported as an error record and the run goes on.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import multiprocessing
import statistics
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

from serpar.calibration.camera_cache import calibrated_pairs
from serpar.errors import ConfigError
from serpar.tasks.episode import run_episode
from serpar.tasks.episode_config import EpisodeConfig, Outcome, wilson_interval
from serpar.tasks.platform_model import prepare_models
from serpar.tasks.ray_runner import ray_results

Record = dict[str, object]
Job = Callable[..., list[Record]]
"""Per-config work: job(cfg, on_hole, label) -> records; module-level so workers can unpickle it."""


def episode_configs(base: EpisodeConfig, episodes: int, first_seed: int | None = None) -> list[EpisodeConfig]:
    """`episodes` configs with consecutive seeds from `first_seed` (default: base.seed)."""
    start = base.seed if first_seed is None else first_seed
    return [dataclasses.replace(base, seed=start + k) for k in range(episodes)]


def recording_folder(root: str | Path, seed: int, label: str | None = None) -> Path:
    """Where an episode's recording goes: ROOT/episode_<seed>/ (ROOT/<label>/... when labelled)."""
    base = Path(root) if label is None else Path(root) / label
    return base / f"episode_{seed}"


def run_one(cfg: EpisodeConfig, on_hole: Callable[[Record], None] | None = None,
            label: str | None = None, record_dir: str | None = None) -> list[Record]:
    """One episode's hole records and its summary record, as plain dicts (picklable);
    `on_hole` (in-process runs only) sees each hole record as it ends; `label` (e.g. the
    ablation arm) is written into every record as "config"; `record_dir` records the episode
    into :func:`recording_folder` (the records are the same either way)."""
    tag = {} if label is None else {"config": label}

    records: list[Record] = []

    def keep(record) -> None:
        records.append({**record.as_dict(), **tag})
        if on_hole:
            on_hole(records[-1])

    try:

        prepare_models([cfg])  # a bad parameters file fails here, before any camera calibration
        folder = None if record_dir is None else recording_folder(record_dir, cfg.seed, label)
        summary = run_episode(cfg, calibrated_pairs(cfg.camera_width), on_record=keep, recording=folder)
        records.append({**summary.as_dict(), **tag})
    except Exception as exc:  # noqa: BLE001 - one bad episode must not end the run
        records.append({"kind": "error", "episode_seed": cfg.seed, "error": f"{type(exc).__name__}: {exc}", **tag})
    return records


def run_many(configs: Sequence[EpisodeConfig], workers: int = 1,
             on_records: Callable[[list[Record]], None] | None = None,
             on_hole: Callable[[Record], None] | None = None,
             labels: Sequence[str | None] | None = None, record_dir: str | None = None,
             job: Job | None = None, ray_address: str | None = None) -> list[Record]:
    """Run every config; `on_records` gets each episode's records as it finishes, `on_hole`
    each hole record as it ends (in-process runs; workers report per episode); `labels[k]`
    tags config k's records; `record_dir` records every episode (see :func:`run_one`); `job`
    replaces :func:`run_one`; `ray_address` runs the episodes on Ray instead of local workers
    (:mod:`serpar.tasks.ray_runner`). On Ctrl-C the records of finished episodes are returned and the
    workers are stopped."""
    out: list[Record] = []
    tags = list(labels) if labels is not None else [None] * len(configs)
    if len(tags) != len(configs):
        raise ValueError(f"{len(tags)} labels for {len(configs)} configs")
    if ray_address is not None and workers > 1:
        raise ConfigError(f"--ray and --workers {workers}: choose one (Ray places the episodes on its own CPUs)")
    work = job or run_one  # looked up now, not at import: tests replace run_one
    if record_dir is not None:
        work = functools.partial(work, record_dir=record_dir)
    results = _results(configs, workers, on_hole, tags, work, ray_address)
    try:
        for records in results:
            out += records
            if on_records:
                on_records(records)
    except KeyboardInterrupt:
        out.append({"kind": "interrupted", "episodes_done": sum(r["kind"] == "episode" for r in out)})
    finally:
        results.close()  # stops the workers now, not whenever the generator is collected
    return out


def _results(configs: Sequence[EpisodeConfig], workers: int, on_hole: Callable[[Record], None] | None,
             labels: Sequence[str | None], job: Job, ray_address: str | None) -> Iterator[list[Record]]:
    if ray_address is not None:

        yield from ray_results(configs, labels, job, ray_address)
        return
    if workers <= 1:
        for cfg, label in zip(configs, labels):
            yield job(cfg, on_hole, label)
        return
    # spawn, not fork: a child forked after this process has rendered inherits its EGL context
    # and can hang in the first render (seen in `serpar bench --episode`).
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        pending: set[Future] = {pool.submit(job, cfg, None, label) for cfg, label in zip(configs, labels)}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                yield fut.result()
    finally:
        pool.shutdown(wait=False, cancel_futures=True)


@dataclass(frozen=True)
class RunSummary:
    episodes: int
    holes: int
    successes: int
    success_rate: float
    wilson95: tuple[float, float]
    counts: dict[str, int]
    sim_faults: int
    cycle_time_s: dict[str, float]
    peak_force_n: dict[str, float]
    errors: int

    def as_dict(self) -> dict[str, object]:
        return {"kind": "summary", **dataclasses.asdict(self)}


def _stats(values: list[float]) -> dict[str, float]:
    values = [v for v in values if not math.isnan(v)]
    if not values:
        return {"mean": float("nan"), "max": float("nan")}
    return {"mean": statistics.fmean(values), "max": max(values)}


def summarise(records: Sequence[Record]) -> RunSummary:
    holes = [r for r in records if r["kind"] == "hole"]
    counts = {o.value: sum(r["outcome"] == o.value for r in holes) for o in Outcome}
    n, ok = len(holes), counts[Outcome.SUCCESS.value]
    return RunSummary(
        episodes=sum(r["kind"] == "episode" for r in records), holes=n, successes=ok,
        success_rate=ok / n if n else float("nan"),
        wilson95=wilson_interval(ok, n) if n else (float("nan"), float("nan")),
        counts=counts, sim_faults=sum(bool(r["sim_fault"]) for r in holes),
        cycle_time_s=_stats([float(r["cycle_time_s"]) for r in holes]),
        peak_force_n=_stats([float(r["peak_force_n"]) for r in holes]),
        errors=sum(r["kind"] == "error" for r in records))
