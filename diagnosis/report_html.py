"""The HTML report of a diagnosis: verdict, where (table + plot), what (ranked effects with
evidence and parameters), before/after held-out residual plots (PNG embedded as base64), and
the updated model written as JSON beside it (plus the family's own model files, when its
domain has any: the Stewart parameters ``serpar run`` reads)."""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

import numpy as np

from serpar.diagnosis.family import LocateRow, export_model_files
from serpar.diagnosis.report_units import section as units_section
from serpar.diagnosis.result import Diagnosis
from serpar.sim.strict_json import dumps


def _png(fig) -> str:  # type: ignore[no-untyped-def]
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _where_plot(before: tuple[LocateRow, ...], after: tuple[LocateRow, ...]) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [f"{r.channel} | {r.label}" for r in before]
    after_by = {(r.channel, r.group, r.label): r.rms_whitened for r in after}
    fig, ax = plt.subplots(figsize=(8, 0.3 * len(labels) + 1.2))
    y = np.arange(len(labels))
    ax.barh(y - 0.2, [r.rms_whitened for r in before], 0.4, label="nominal (baseline fitted)")
    ax.barh(y + 0.2, [after_by.get((r.channel, r.group, r.label), np.nan) for r in before], 0.4,
            label="with the selected effects")
    ax.axvline(1.0, color="k", ls="--", lw=1, label="noise floor")
    ax.set_yticks(y, labels, fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("RMS of residual / noise sigma")
    ax.invert_yaxis()
    ax.legend(fontsize=7)
    return _png(fig)


def _heldout_plot(diag: Diagnosis) -> str:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.2))
    for w, label in ((diag.heldout_before, "before"), (diag.heldout_after, "after")):
        axes[0].plot(np.abs(w), ".", ms=2, label=f"{label}: RMS {np.sqrt(np.mean(w**2)):.3g}")
    axes[0].axhline(1.0, color="k", ls="--", lw=1)
    axes[0].set_yscale("log")
    axes[0].set_xlabel("held-out residual entry")
    axes[0].set_ylabel("|residual| / sigma")
    axes[0].legend(fontsize=7)
    lim = max(4.0, float(np.percentile(np.abs(diag.heldout_after), 99.5)) if diag.heldout_after.size else 4.0)
    bins = np.linspace(-lim, lim, 60)
    axes[1].hist(np.clip(diag.heldout_after, -lim, lim), bins, density=True, alpha=0.7,
                 label="after")
    g = np.linspace(-lim, lim, 200)
    axes[1].plot(g, np.exp(-g**2 / 2) / np.sqrt(2 * np.pi), "k--", lw=1, label="noise N(0,1)")
    axes[1].set_xlabel("held-out residual / sigma (after)")
    axes[1].legend(fontsize=7)
    return _png(fig)


def _table(headers: list[str], rows: list[list[object]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>"
                   for r in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def write_report(diag: Diagnosis, path: str | Path, source: str, family: object = None
                 ) -> tuple[Path, Path, list[Path]]:
    """Write the HTML report, ``<stem>.model.json`` and the files of the family's ``export``
    hook (``<stem>.<what>``, none without a hook); returns the three."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    model_path = out.with_name(out.stem + ".model.json")
    model_path.write_text(dumps(diag.model_file(source), indent=2))
    exported = export_model_files(family, diag.model, out.with_name(out.stem))
    where = _table(["channel", "split by", "label", "n", "RMS/sigma", "p (chi-square)", "flag"],
                   [[r.channel, r.group, r.label, r.n, f"{r.rms_whitened:.3g}",
                     f"{r.p_value:.2g}", "BEYOND NOISE" if r.flagged else ""]
                    for r in diag.locate_before])
    what = "".join(f"<li>{html.escape(f.words())}<br><small>"
                   + html.escape("; ".join(p.words() for p in f.params)) + "</small></li>"
                   for f in diag.findings) or "<li>none</li>"
    cands = _table(["step", "effect", "k", "dBIC train", "held-out chi2 drop",
                    "held-out RMS/sigma", "earns"],
                   [[c.step, c.effect, c.n_params, f"{c.delta_bic_train:.1f}",
                     f"{c.delta_chi2_heldout:.1f}", f"{c.heldout_rms:.3g}",
                     "yes" if c.earns else "no"] for c in diag.candidates])
    doc = f"""<!doctype html><html><head><meta charset="utf-8"><title>serpar diagnose</title>
<style>body{{font-family:sans-serif;max-width:1000px;margin:2em auto}}table{{border-collapse:collapse;font-size:12px}}
td,th{{border:1px solid #ccc;padding:2px 6px}}</style></head><body>
<h1>serpar diagnose: {html.escape(source)}</h1>
<p><b>{html.escape(diag.kind)}</b>: {diag.n_train_rows} training rows, {diag.n_heldout_rows} held-out rows, {diag.wall_s:.1f} s.</p>
<h2>Verdict</h2><p><b>{html.escape(diag.verdict)}</b></p>
<p>Held-out RMS of residual/sigma: {diag.heldout_rms_before:.3g} (nominal, baseline fitted) &rarr;
{diag.heldout_rms_after:.3g} (noise floor 1; chi-square p = {diag.heldout_p_after:.2g});
explained share of the excess held-out residual: {100 * diag.explained:.1f} %.</p>
<h2>What</h2><ol>{what}</ol>
<h2>Where</h2><img src="data:image/png;base64,{_where_plot(diag.locate_before, diag.locate_after)}">{where}
{units_section(diag.physical, _png)}
<h2>Held-out residual before and after (whitened)</h2><img src="data:image/png;base64,{_heldout_plot(diag)}">
<h2>Evidence: every candidate tried</h2>{cands}
<p>Updated model: <code>{html.escape(model_path.name)}</code>{_exported(exported)}</p></body></html>"""
    out.write_text(doc)
    return out, model_path, exported


def _exported(paths: list[Path]) -> str:
    if not paths:
        return ""
    names = ", ".join(f"<code>{html.escape(p.name)}</code>" for p in paths)
    return f"; for <code>serpar run</code>: {names}"
