"""``serpar sim2real``: does the simulator predict what the assembly does on a real cell, and
does a diagnosis of that cell's recordings make it predict better?

1. Read the real cell's episode recordings (``serpar run --record`` layout: its log's seed,
   holes and task keys; tasks/episode_config.py ``CELL_LOG_KEYS``), never the physics.
2. Rerun the simulator on the same seeds and holes (the nominal cell, or ``--model M``) and
   compare per hole (diagnosis/task_outcomes.py): each outcome's mean paired difference,
   real minus simulated, with its 95 % t interval over the holes.
3. Diagnose the real recordings against that simulator (established findings only), write
   the updated model (``updated.model.json``, ``updated.xml``), rerun with it, compare again.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import stats

from serpar.calibration.camera_cache import calibrated_pairs
from serpar.diagnosis.bore_friction import MU_RANGE as BORE_MU_RANGE
from serpar.diagnosis.choose import family_from_recording, load_for_diagnosis
from serpar.diagnosis.config_model import model_from_config
from serpar.diagnosis.prior import PriorFamily
from serpar.diagnosis.result import Diagnosis
from serpar.diagnosis.select import default_config, diagnose
from serpar.diagnosis.task_outcomes import OUTCOMES, RESOLUTION, HoleOutcome, hole_outcomes
from serpar.errors import ConfigError
from serpar.sim.mjcf_export import MjcfExport, export_arm_mjcf
from serpar.sim.model_file import parse_model
from serpar.sim.physics import PhysicsConfig
from serpar.tasks.episode import run_episode
from serpar.tasks.episode_config import CELL_LOG_KEYS, EpisodeConfig
from serpar.tasks.run_episodes import recording_folder

Tick = Callable[[str], None]
NOMINAL_MU = PhysicsConfig().precision_friction
MU_RANGE = BORE_MU_RANGE


@dataclass(frozen=True)
class RealEpisode:
    folder: Path
    config: EpisodeConfig
    """The rerun: the log's seed, holes and task keys, on the nominal physics."""
    notes: tuple[str, ...]


@dataclass(frozen=True)
class OutcomeDiff:
    diff: float | None
    """Mean of real minus simulated over the holes where both have a value."""
    ci: float | None
    """Half-width of its 95 % t interval (None with fewer than 2 holes)."""
    n: int
    pairs: tuple[float, ...]

    def as_dict(self) -> dict[str, object]:
        return {"diff": self.diff, "ci": self.ci, "n": self.n}

    def words(self) -> str:
        if self.diff is None:
            return "-"
        return f"{self.diff:+.4g}" + (f" ± {self.ci:.3g}" if self.ci is not None else " (n < 2)")


def beyond_ci(name: str, d: OutcomeDiff) -> bool:
    """The difference is beyond its CI and beyond what the outcome is measured to."""
    return (d.diff is not None and d.ci is not None
            and abs(d.diff) > max(d.ci, RESOLUTION.get(name, 0.0)) + 1e-12)


def real_episodes(real_dir: str | Path, seed: int = 0) -> list[RealEpisode]:
    """The episode recordings in ``real_dir`` (``episode_*`` folders, or the folder itself)."""
    root = Path(real_dir)
    if not root.is_dir():
        raise ConfigError(f"{root} is not a folder of serpar run --record episodes")
    folders = sorted(p for p in root.iterdir() if p.is_dir() and (p / "meta.json").is_file())
    if (root / "meta.json").is_file():
        folders = [root]
    if not folders:
        raise ConfigError(f"{root}: no episode recordings (folders with a meta.json, as serpar "
                          "run --record writes them)")
    return [_episode(f, seed) for f in folders]


def _episode(folder: Path, seed: int) -> RealEpisode:
    meta = json.loads((folder / "meta.json").read_text())
    model = meta.get("model") or {}
    log = model.get("cell_log") or model.get("episode_config") or {}
    notes: list[str] = []
    keys = {k: log[k] for k in CELL_LOG_KEYS if k in log and k not in ("seed", "holes")}
    if "seed" not in log:
        notes.append(f"{folder.name}: the log gives no seed: part dimensions and the platform's "
                     f"errors drawn from the tolerance distributions with seed {seed}")
    holes = [r.get("hole") for r in meta.get("holes") or []]
    if not holes or any(h is None for h in holes):
        raise ConfigError(f"{folder}: hole records without a hole index: the simulator cannot "
                          "be rerun on the same holes")
    if isinstance(keys.get("stewart_calibration"), str) and keys["stewart_calibration"] not in (
            "campaign", "none") and not Path(keys["stewart_calibration"]).is_file():
        notes.append(f"{folder.name}: its calibration file {keys['stewart_calibration']} is not "
                     "here; the simulator calibrates its platform by the campaign")
        keys["stewart_calibration"] = "campaign"
    cfg = EpisodeConfig(seed=int(log.get("seed", seed)), holes=tuple(int(h) for h in holes), **keys)
    return RealEpisode(folder, cfg, tuple(notes))


def rerun(episodes: list[RealEpisode], out: Path, plant_model: str | None,
          contact_friction: float | None, tick: Tick) -> list[Path]:
    """Record the simulator on each episode's seed and holes into ``out`` (a recording a
    Ctrl-C stops is left as far as it got, the finished ones whole)."""
    folders = []
    for k, ep in enumerate(episodes):
        cfg = dataclasses.replace(ep.config, plant_model=plant_model,
                                  contact_friction=contact_friction)
        folder = recording_folder(out, cfg.seed)
        what = f"{out.name} rerun {k + 1} of {len(episodes)}"
        holes = cfg.holes if isinstance(cfg.holes, int) else len(cfg.holes)
        tick(f"{what}: seed {cfg.seed}, {holes} hole{'s' * (holes != 1)}")
        run_episode(cfg, calibrated_pairs(cfg.camera_width), recording=folder,
                    on_record=lambda r, what=what: tick(f"{what}: hole {r.hole} {r.outcome}"))
        folders.append(folder)
    return folders


def compare(real: list[HoleOutcome], sim: list[HoleOutcome]) -> dict[str, OutcomeDiff]:
    """Per outcome the mean paired difference (real - sim) over the holes, with its 95 % CI."""
    by_hole = {(h.cycle, h.hole): h for h in sim}
    return {name: paired([r.values[name] - by_hole[(r.cycle, r.hole)].values[name] for r in real
                          if (r.cycle, r.hole) in by_hole]) for name in OUTCOMES}


def paired(pairs: list[float]) -> OutcomeDiff:
    """The mean of per-hole differences (non-finite ones left out) and its 95 % t interval."""
    d = np.array([p for p in pairs if math.isfinite(p)])
    mean = float(d.mean()) if d.size else None
    ci = (float(stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / math.sqrt(d.size))
          if d.size >= 2 else None)
    return OutcomeDiff(mean, ci, int(d.size), tuple(float(x) for x in d))


def outcomes_of(folders: list[Path]) -> list[HoleOutcome]:
    """Every hole of the recordings, keyed apart by the recording's order (cycle + 1000 k)."""
    out = []
    for k, folder in enumerate(folders):
        out += [dataclasses.replace(h, cycle=h.cycle + 1000 * k) for h in hole_outcomes(folder)]
    return out


def diagnose_cell(episodes: list[RealEpisode], nominal: EpisodeConfig, source: str, seed: int,
                  report: Tick | None = None, workers: int = 0
                  ) -> tuple[Diagnosis, dict[str, object], list[str]]:
    """Diagnose the longest recording against the simulator ``nominal`` builds (its fits on
    ``workers`` processes, 0: every core); the combined model (the simulator's effects
    updated by what the recording shows) and notes."""
    longest = max(episodes, key=lambda e: len(e.config.holes))  # type: ignore[arg-type]
    notes = [f"{e.folder.name}: not diagnosed (the longest recording, {longest.folder.name}, is)"
             for e in episodes if e is not longest]
    family = PriorFamily(family_from_recording(load_for_diagnosis(longest.folder)),
                         model_from_config(nominal, source))
    diag = diagnose(family, seed, default_config(family, workers), report)
    diag = dataclasses.replace(diag, model=family.combined_model(diag.model))
    return diag, diag.model_file(str(longest.folder)), notes


def updated_contact_friction(model: dict[str, object]) -> float | None:
    """The rerun's journal/bore friction from an updated model (None: the nominal one)."""
    if "contact_friction" not in model.get("effects", []):  # type: ignore[operator]
        return None
    d_mu = float(model["params"]["contact_friction"]["values"][0])  # type: ignore[index]
    return float(np.clip(NOMINAL_MU + d_mu, *MU_RANGE))


def write_model_file(model: dict[str, object], out: Path) -> Path:
    """``updated.model.json`` of the updated model (what a rerun's plant reads)."""
    path = out / "updated.model.json"
    path.write_text(json.dumps(model, indent=2))
    return path


def write_updated(model: dict[str, object], out: Path) -> tuple[Path, MjcfExport]:
    """``updated.model.json`` and ``updated.xml`` of the updated model."""
    path = write_model_file(model, out)
    return path, export_arm_mjcf(parse_model(model, str(path)), out / "updated.xml")


def carried_words(diag: Diagnosis, model: dict[str, object]) -> str:
    """What the updated model carries that is not established (one of an "A or B" pair: a
    model must hold one of the two), with why, for the verdict ("" when nothing)."""
    effects = model["effects"]
    return "".join(f"; the updated model carries {f.effect}, not established: "
                   f"{'; '.join(f.reasons)}" for f in diag.findings
                   if not f.established and f.effect in effects)  # type: ignore[operator]


def established(diag: Diagnosis, model: dict[str, object]) -> list[dict[str, object]]:
    """The established effects with their values in the updated model (a correction's value
    is the simulator's plus the correction) and the diagnosis's sigma."""
    blocks = model["params"]
    out = []
    for f in diag.established:
        b = blocks[f.effect]  # type: ignore[index]
        out.append({"effect": f.effect, "params": {n: [v, s] for n, v, s in
                                                   zip(b["names"], b["values"], b["std"])}})
    return out
