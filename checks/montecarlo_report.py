"""The report of ``serpar montecarlo``: the yield with its interval, outcome counts, where the
failures lie over (lateral error at the start, tilt, clearance), peak-force distributions and
which error source drives the failures; one HTML file with its plots inline."""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from serpar.checks.montecarlo import MonteCarloResult, sensitivity
from serpar.checks.montecarlo_config import SOURCES
from serpar.diagnosis.report_html import _png


def _pyplot():  # type: ignore[no-untyped-def]
    """matplotlib's pyplot on the file backend, imported when a report is written (it costs
    every other command its start-up time)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


OUTCOME_COLOURS = {"success": "tab:green", "jam": "tab:red", "align_fail": "tab:orange",
                   "timeout": "tab:purple", "overforce": "tab:brown", "sim_fault": "black"}


def _column(result: MonteCarloResult, key: str) -> np.ndarray:
    return np.array([r.as_dict()[key] for r in result.rows], dtype=object)


def success_map(result: MonteCarloResult) -> str:
    """Each trial at its lateral error and tilt at the start (left) and its lateral error and
    clearance (right), seated or not: a base64 PNG."""
    outcome = _column(result, "outcome")
    lateral = _column(result, "start_lateral_mm").astype(float)
    tilt = _column(result, "start_tilt_deg").astype(float)
    clearance = _column(result, "clearance_um").astype(float)
    fig, axes = _pyplot().subplots(1, 2, figsize=(12, 4.5))
    for ax, y, label in ((axes[0], tilt, "tilt between journal and hole at the start [deg]"),
                         (axes[1], clearance, "diametral clearance [um]")):
        for name in sorted(set(outcome), key=lambda n: n != "success"):  # failures drawn on top
            sel = outcome == name
            ok = name == "success"
            ax.scatter(lateral[sel], y[sel], s=8 if ok else 30, alpha=0.5 if ok else 0.9,
                       marker="o" if ok else "x", label=f"{name} ({int(sel.sum())})",
                       color=OUTCOME_COLOURS.get(name, "black"))
        ax.set_xlabel("true journal tip off the hole axis at the start [mm]")
        ax.set_ylabel(label)
        ax.legend(fontsize=8)
    fig.suptitle(f"{len(result.rows)} trials, seed {result.seed}")
    fig.tight_layout()
    return _png(fig)


def force_plot(result: MonteCarloResult) -> str:
    """Peak contact force (1 ms means) per outcome: a base64 PNG."""
    outcome = _column(result, "outcome")
    peak = _column(result, "peak_force_n").astype(float)
    fig, ax = _pyplot().subplots(figsize=(7, 4))
    names = sorted(set(outcome), key=lambda n: n != "success")
    ax.hist([peak[outcome == n] for n in names], bins=30, stacked=True, label=list(names),
            color=[OUTCOME_COLOURS.get(n, "black") for n in names])
    ax.set_xlabel("peak contact force between part and plate [N]")
    ax.set_ylabel("trials")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _png(fig)


def sensitivity_rows(result: MonteCarloResult) -> list[tuple[str, float | None, float, float]]:
    """(source, AUC, mean size among seated, mean size among failed) per error source."""
    auc = sensitivity(result)
    ok = _column(result, "outcome") == "success"
    rows = []
    for src in SOURCES:
        size = _column(result, f"{src}_size").astype(float)
        rows.append((src, auc[src], float(size[ok].mean()) if ok.any() else float("nan"),
                     float(size[~ok].mean()) if (~ok).any() else float("nan")))
    return rows


def write_montecarlo_report(result: MonteCarloResult, path: Path) -> Path:
    lo, hi = result.wilson95
    counts = "".join(f"<tr><td>{html.escape(k)}</td><td>{v}</td></tr>" for k, v in result.counts.items())
    sens = "".join(
        f"<tr><td>{s}</td><td>{'-' if a is None else f'{a:.3f}'}</td><td>{ok:.4g}</td><td>{bad:.4g}</td></tr>"
        for s, a, ok, bad in sensitivity_rows(result))
    state = " (interrupted: the trials that finished)" if result.interrupted else ""
    doc = f"""<!doctype html><html><head><meta charset="utf-8"><title>serpar montecarlo</title>
<style>body{{font-family:sans-serif;max-width:1200px;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:2px 8px}}</style></head><body>
<h1>serpar montecarlo: first-pass yield by physics</h1>
<p>{len(result.rows)} of {result.trials_asked} trials{state}, seed {result.seed}, {result.wall_s:.0f} s.
Seated first time: <b>{100 * result.success_rate:.2f} %</b> (Wilson 95 %: {100 * lo:.2f}–{100 * hi:.2f} %).</p>
<h2>Outcomes</h2><table><tr><th>outcome</th><th>trials</th></tr>{counts}</table>
<h2>Where the failures lie</h2><img src="data:image/png;base64,{success_map(result)}">
<h2>Peak forces</h2><img src="data:image/png;base64,{force_plot(result)}">
<h2>Which error drives the failures</h2>
<p>AUC: the probability that a failed trial drew more of the source than a seated one (0.5: no
bearing; near 1: the failures are the large draws; near 0: the small ones, as tight fits are
for the clearance). Sizes: lateral errors and the clearance in metres, tilts in radians.</p>
<table><tr><th>source</th><th>AUC</th><th>mean size, seated</th><th>mean size, failed</th></tr>{sens}</table>
</body></html>"""
    path.write_text(doc)
    return path
