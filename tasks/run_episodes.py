"""Many episodes: seeds -> records, in this process or in worker processes, and the summary.

Each episode depends only on its config (seed included), so a run with W workers gives the
same records as a serial run. Records stream to a callback as they arrive (JSON lines on
the command line); an interrupted run keeps every episode that finished. An episode that
raises is reported as an error record and the run goes on.
"""

from __future__ import annotations

import dataclasses
import math
import statistics
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass

from tasks.episode_config import EpisodeConfig, Outcome, wilson_interval

Record = dict[str, object]


def episode_configs(base: EpisodeConfig, episodes: int, first_seed: int | None = None) -> list[EpisodeConfig]:
    """`episodes` configs with consecutive seeds from `first_seed` (default: base.seed)."""
    start = base.seed if first_seed is None else first_seed
    return [dataclasses.replace(base, seed=start + k) for k in range(episodes)]


def run_one(cfg: EpisodeConfig, on_hole: Callable[[Record], None] | None = None,
            label: str | None = None) -> list[Record]:
    """One episode's hole records and its summary record, as plain dicts (picklable);
    `on_hole` (in-process runs only) sees each hole record as it ends; `label` (e.g. the
    ablation arm) is written into every record as "config"."""
    tag = {} if label is None else {"config": label}
    from tasks.camera_cache import calibrated_pairs
    from tasks.episode import run_episode

    records: list[Record] = []

    def keep(record) -> None:
        records.append({**record.as_dict(), **tag})
        if on_hole:
            on_hole(records[-1])

    try:
        summary = run_episode(cfg, calibrated_pairs(cfg.camera_width), on_record=keep)
        records.append({**summary.as_dict(), **tag})
    except Exception as exc:  # noqa: BLE001 - one bad episode must not end the run
        records.append({"kind": "error", "episode_seed": cfg.seed, "error": f"{type(exc).__name__}: {exc}", **tag})
    return records


def run_many(configs: Sequence[EpisodeConfig], workers: int = 1,
             on_records: Callable[[list[Record]], None] | None = None,
             on_hole: Callable[[Record], None] | None = None,
             labels: Sequence[str | None] | None = None) -> list[Record]:
    """Run every config; `on_records` gets each episode's records as it finishes, `on_hole`
    each hole record as it ends (in-process runs; workers report per episode); `labels[k]`
    tags config k's records. On Ctrl-C the records of finished episodes are returned and the
    workers are stopped."""
    out: list[Record] = []
    tags = list(labels) if labels is not None else [None] * len(configs)
    if len(tags) != len(configs):
        raise ValueError(f"{len(tags)} labels for {len(configs)} configs")
    try:
        for records in _results(configs, workers, on_hole, tags):
            out += records
            if on_records:
                on_records(records)
    except KeyboardInterrupt:
        out.append({"kind": "interrupted", "episodes_done": sum(r["kind"] == "episode" for r in out)})
    return out


def _results(configs: Sequence[EpisodeConfig], workers: int, on_hole: Callable[[Record], None] | None,
             labels: Sequence[str | None]) -> Iterator[list[Record]]:
    if workers <= 1:
        for cfg, label in zip(configs, labels):
            yield run_one(cfg, on_hole, label)
        return
    pool = ProcessPoolExecutor(max_workers=workers)
    try:
        pending: set[Future] = {pool.submit(run_one, cfg, None, label) for cfg, label in zip(configs, labels)}
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
