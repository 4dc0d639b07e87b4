"""Many episodes: seeds -> records, in this process, in worker processes or on Ray
(:mod:`serpar.tasks.ray_runner`), and the summary.

Each episode depends only on its config (seed included), so a run with W workers gives the
same records as a serial run. Records stream to a callback as they arrive (JSON lines on
the command line); an interrupted run keeps every hole that finished, the interrupted
episodes' records marked ``complete: false``, and says where it stopped. An episode that
raises is reported as an error record (after the holes it finished) and the run goes on; so
does a run whose worker process dies (:mod:`serpar.tasks.local_pool`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import statistics
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from serpar.calibration.camera_cache import calibrated_pairs
from serpar.errors import ConfigError
from serpar.tasks.episode import EpisodeInterrupted, run_episode, signal_name
from serpar.tasks.episode_config import EpisodeConfig, Outcome, wilson_interval
from serpar.tasks.local_pool import LocalPool
from serpar.tasks.platform_model import prepare_models
from serpar.tasks.ray_runner import ray_results

Record = dict[str, object]
Job = Callable[..., list[Record]]
"""Per-config work: job(cfg, on_hole, label) -> records; module-level so workers can unpickle it."""
INTERRUPTED = "interrupted"


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
    into :func:`recording_folder` (the records are the same either way).

    Never raises for one episode: an exception gives the holes that finished and an error
    record; an interrupt gives the holes that finished, the episode's record with
    ``complete: false`` and an "interrupted" record saying where it stopped (signal, episode,
    cycle, hole, phase), which ends the run."""
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
    except EpisodeInterrupted as stop:
        records += [{**stop.summary.as_dict(), **tag}, {"kind": INTERRUPTED, **stop.where, **tag}]
    except KeyboardInterrupt as exc:  # before the episode's first step (or a second one while it closed)
        records.append({"kind": INTERRUPTED, "signal": signal_name(exc), "episode": cfg.seed, "cycle": None,
                        "hole": None, "phase": None if records else "setup", **tag})
    except Exception as exc:  # noqa: BLE001 - one bad episode must not end the run
        records.append({"kind": "error", "episode_seed": cfg.seed, "error": f"{type(exc).__name__}: {exc}", **tag})
    return records


def run_many(configs: Sequence[EpisodeConfig], workers: int = 1,
             on_records: Callable[[list[Record]], None] | None = None,
             on_hole: Callable[[Record], None] | None = None,
             labels: Sequence[str | None] | None = None, record_dir: str | None = None,
             job: Job | None = None, ray_address: str | None = None,
             notify: Callable[[str], None] | None = None) -> list[Record]:
    """Run every config; `on_records` gets each episode's records as it finishes, `on_hole`
    each hole record as it ends (in-process runs; workers report per episode); `labels[k]`
    tags config k's records; `record_dir` records every episode (see :func:`run_one`); `job`
    replaces :func:`run_one`; `ray_address` runs the episodes on Ray instead of local workers
    (:mod:`serpar.tasks.ray_runner`).

    On an interrupt (KeyboardInterrupt here, or an episode's "interrupted" record) the run
    stops: local workers close their episodes first (:mod:`serpar.tasks.local_pool`; `notify`
    is told while they do), what finished is returned, and the last record is the run's
    "interrupted" record (:func:`interrupted_record`). The episodes' own "interrupted" records
    are folded into it and not passed to `on_records`."""
    out: list[Record] = []
    tags = list(labels) if labels is not None else [None] * len(configs)
    if len(tags) != len(configs):
        raise ValueError(f"{len(tags)} labels for {len(configs)} configs")
    if ray_address is not None and workers > 1:
        raise ConfigError(f"--ray and --workers {workers}: choose one (Ray places the episodes on its own CPUs)")
    work = job or run_one  # looked up now, not at import: tests replace run_one
    if record_dir is not None:
        work = functools.partial(work, record_dir=record_dir)
    stopped: list[Record] = []
    signal: str | None = None

    def take(records: list[Record]) -> None:
        stopped.extend(r for r in records if r["kind"] == INTERRUPTED)
        mine = [r for r in records if r["kind"] != INTERRUPTED]
        out.extend(mine)
        if on_records:
            on_records(mine)

    source = _Source(configs, workers, on_hole, tags, work, ray_address)
    try:
        for records in source:
            take(records)
            if stopped:
                break
    except KeyboardInterrupt as exc:
        signal = signal_name(exc)
    finally:
        late = source.stop(signal is not None, notify)
    for records in late:
        take(records)
    if signal is not None or stopped:
        out.append(interrupted_record(out, stopped, signal or str(stopped[0]["signal"]), len(configs)))
    return out


def interrupted_record(records: Sequence[Record], stopped: Sequence[Record], signal: str,
                       n_configs: int) -> Record:
    """The run's "interrupted" record: the signal; where the first stopped episode was
    (episode seed, cycle, hole, phase; None when no episode was under way); every stopped
    episode; how many episodes completed and how many never started."""
    where = [{k: v for k, v in r.items() if k not in ("kind", "signal")} for r in stopped]
    where.sort(key=lambda w: (str(w.get("config")), int(w["episode"])))  # type: ignore[call-overload]
    first = where[0] if where else {}
    started = {(r.get("config"), r.get("seed", r.get("episode_seed"))) for r in records
               if r["kind"] in ("episode", "error")} | {(w.get("config"), w["episode"]) for w in where}
    return {"kind": INTERRUPTED, "signal": signal, **{k: first.get(k) for k in ("episode", "cycle", "hole", "phase")},
            "stopped": where, "episodes_done": sum(r["kind"] == "episode" and r.get("complete", True) is not False
                                                   for r in records),
            "episodes_not_started": n_configs - len(started)}


class _Source:
    """Each config's records as its episode finishes: in this process, in local workers or on
    Ray; :meth:`stop` ends the run (and, interrupted, gathers what the workers finished)."""

    def __init__(self, configs: Sequence[EpisodeConfig], workers: int, on_hole: Callable[[Record], None] | None,
                 labels: Sequence[str | None], job: Job, ray_address: str | None) -> None:
        self.pool = LocalPool(configs, labels, job, workers) if workers > 1 and ray_address is None else None
        if ray_address is not None:
            self.results: Iterator[list[Record]] = ray_results(configs, labels, job, ray_address)
        elif self.pool is not None:
            self.results = iter(self.pool)
        else:
            self.results = (job(cfg, on_hole, label) for cfg, label in zip(configs, labels))

    def __iter__(self) -> Iterator[list[Record]]:
        return self.results

    def stop(self, interrupted: bool, notify: Callable[[str], None] | None) -> list[list[Record]]:
        getattr(self.results, "close", lambda: None)()  # Ray: cancels the pending tasks now
        return self.pool.stop(interrupted, notify) if self.pool is not None else []


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
    partial_episodes: int = 0
    """Episodes counted in `episodes` that were interrupted before their last hole."""
    interrupted: dict[str, object] | None = None
    """The run's "interrupted" record (without its kind), None for a run that was not."""
    wall_s: float = 0.0
    """Wall time of the episodes, summed (their workers' own clocks) [s]."""
    physics_wall_s: float = 0.0
    """Of it, inside ``mj_step`` (MuJoCo's step timer) [s]."""
    setup_wall_s: float = 0.0
    """Of it, before each episode's first hole cycle (building, settling, registering) [s]."""

    def as_dict(self) -> dict[str, object]:
        return {"kind": "summary", **dataclasses.asdict(self)}


def _stats(values: list[float]) -> dict[str, float]:
    values = [v for v in values if not math.isnan(v)]
    if not values:
        return {"mean": float("nan"), "max": float("nan")}
    return {"mean": statistics.fmean(values), "max": max(values)}


def summarise(records: Sequence[Record]) -> RunSummary:
    """Counts over the records; a success rate and interval of NaN for no holes (null in the
    command line's JSON)."""
    holes = [r for r in records if r["kind"] == "hole"]
    stop = [{k: v for k, v in r.items() if k != "kind"} for r in records if r["kind"] == INTERRUPTED]
    counts = {o.value: sum(r["outcome"] == o.value for r in holes) for o in Outcome}
    n, ok = len(holes), counts[Outcome.SUCCESS.value]
    return RunSummary(
        episodes=sum(r["kind"] == "episode" for r in records), holes=n, successes=ok,
        success_rate=ok / n if n else float("nan"),
        wilson95=wilson_interval(ok, n) if n else (float("nan"), float("nan")),
        counts=counts, sim_faults=sum(bool(r["sim_fault"]) for r in holes),
        cycle_time_s=_stats([float(r["cycle_time_s"]) for r in holes]),
        peak_force_n=_stats([float(r["peak_force_n"]) for r in holes]),
        errors=sum(r["kind"] == "error" for r in records),
        partial_episodes=sum(r["kind"] == "episode" and r.get("complete") is False for r in records),
        interrupted=stop[-1] if stop else None,
        **{k: _total(records, k) for k in ("wall_s", "physics_wall_s", "setup_wall_s")})


def _total(records: Sequence[Record], key: str) -> float:
    """``key`` summed over the episode records that state it (NaN: an episode stopped before)."""
    values = (r.get(key) for r in records if r["kind"] == "episode")
    return math.fsum(float(v) for v in values if v is not None and not math.isnan(float(v)))
