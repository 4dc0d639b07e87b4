"""The HTML report of ``serpar sim2real``: the before/after table and one plot per outcome
(each hole's real-minus-simulated difference, before and after, with the mean and its 95 %
interval)."""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from pathlib import Path

from serpar.checks.sim2real import OutcomeDiff
from serpar.diagnosis.report_html import _png
from serpar.diagnosis.task_outcomes import OUTCOMES


def _plots(before: Mapping[str, OutcomeDiff], after: Mapping[str, OutcomeDiff]) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 4, figsize=(14, 6))
    for ax, name in zip(axes.ravel(), OUTCOMES):
        for x, (label, d) in enumerate((("nominal", before[name]), ("updated", after[name]))):
            ax.plot([x] * len(d.pairs), d.pairs, "o", alpha=0.5, color=f"C{x}")
            if d.diff is not None:
                ax.errorbar(x + 0.15, d.diff, yerr=d.ci or 0.0, fmt="s", color="k", capsize=4)
        ax.axhline(0.0, color="gray", lw=0.8)
        ax.set_xticks([0, 1], ["nominal", "updated"])
        ax.set_title(f"{name} [{OUTCOMES[name]}]", fontsize=10)
        ax.set_xlim(-0.5, 1.5)
    fig.suptitle("real minus simulated, per hole (dots) and mean ± 95 % CI (squares)")
    fig.tight_layout()
    return _png(fig)


def write_sim2real_report(path: Path, real_dir: str, before: Mapping[str, OutcomeDiff],
                          after: Mapping[str, OutcomeDiff], established: Sequence[Mapping[str, object]],
                          notes: Sequence[str], verdict: str) -> Path:
    rows = "".join(
        f"<tr><td>{n}</td><td>{OUTCOMES[n]}</td><td>{before[n].n}</td><td>{before[n].words()}</td>"
        f"<td>{after[n].words()}</td></tr>" for n in OUTCOMES)
    found = "".join(f"<li>{html.escape(str(e['effect']))}: " + html.escape(", ".join(
        f"{k} = {v[0]:.4g} ± {v[1]:.2g}" for k, v in e["params"].items())) + "</li>"  # type: ignore[union-attr]
        for e in established) or "<li>none</li>"
    note = "".join(f"<li>{html.escape(n)}</li>" for n in notes)
    doc = f"""<!doctype html><html><head><meta charset="utf-8"><title>serpar sim2real</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:2em auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:2px 8px}}</style></head><body>
<h1>serpar sim2real: {html.escape(real_dir)}</h1>
<p>{html.escape(verdict)}</p>
<h2>Outcomes: real minus simulated (mean ± 95 % CI over the holes)</h2>
<table><tr><th>outcome</th><th>unit</th><th>holes</th><th>nominal simulator</th><th>updated simulator</th></tr>{rows}</table>
<img src="data:image/png;base64,{_plots(before, after)}">
<h2>Established by the diagnosis</h2><ul>{found}</ul>
<h2>Notes</h2><ul>{note or '<li>none</li>'}</ul></body></html>"""
    path.write_text(doc)
    return path
