"""The report's physical-unit part: per channel, the held-out traces (recorded, nominal model,
fitted model) and residuals before and after the fit in the channel's unit, and a table of
their RMS next to the channel's noise sigma."""

from __future__ import annotations

import html

import numpy as np

from serpar.diagnosis.units import PhysicalResidual

MAX_PANELS = 16
"""Channels shown as plots (the table lists them all)."""


def _grid(n: int):  # type: ignore[no-untyped-def]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = 2 if n > 1 else 1
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(10, 1.9 * rows + 0.6), squeeze=False,
                             sharex=True)
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    return fig, axes.ravel()


def _panels(p: PhysicalResidual, traces: bool) -> list[int]:
    v = p.view
    shown = [c for c in range(len(v.channels)) if np.any(v.channel == c)]
    if traces:
        shown = [c for c in shown if v.measured is not None
                 and np.all(np.isfinite(v.measured[v.channel == c]))]
    return shown[:MAX_PANELS]


def _each(p: PhysicalResidual, shown: list[int]):  # type: ignore[no-untyped-def]
    """(figure, [(axes, channel, its entries in axis order)]) with each panel labelled."""
    v = p.view
    fig, axes = _grid(len(shown))
    panels = []
    for ax, c in zip(axes, shown, strict=False):
        m = np.flatnonzero(v.channel == c)
        panels.append((ax, c, m[np.argsort(v.axis[m], kind="stable")]))
        ax.set_ylabel(f"{v.channels[c]} [{v.units[c]}]", fontsize=7)
        ax.tick_params(labelsize=6)
    for ax in axes[-2:]:
        ax.set_xlabel(f"held-out rows: {v.axis_label}", fontsize=7)
    return fig, panels


def traces_plot(p: PhysicalResidual, png) -> str | None:  # type: ignore[no-untyped-def]
    """Recorded against the nominal and the fitted model (recorded minus each residual)."""
    v = p.view
    shown = _panels(p, traces=True)
    if not shown or v.measured is None:
        return None
    fig, panels = _each(p, shown)
    for ax, _, m in panels:
        x, y = v.axis[m], v.measured[m]
        ax.plot(x, y, ".", color="k", ms=2, label="recorded")
        ax.plot(x, y - p.before[m], ".", color="tab:orange", ms=1.5, label="nominal model")
        ax.plot(x, y - p.after[m], ".", color="tab:blue", ms=1.5, label="fitted model")
    panels[0][0].legend(fontsize=6, loc="best")
    return png(fig)


def residual_plot(p: PhysicalResidual, png) -> str | None:  # type: ignore[no-untyped-def]
    v = p.view
    shown = _panels(p, traces=False)
    if not shown:
        return None
    fig, panels = _each(p, shown)
    for ax, _, m in panels:
        sigma = float(np.median(v.scale[m]))
        ax.plot(v.axis[m], p.before[m], ".", color="tab:orange", ms=1.5, label="before")
        ax.plot(v.axis[m], p.after[m], ".", color="tab:blue", ms=1.5, label="after")
        ax.axhspan(-sigma, sigma, color="0.85", zorder=0, label="± noise sigma")
    panels[0][0].legend(fontsize=6, loc="best")
    return png(fig)


def rms_table(p: PhysicalResidual) -> str:
    v = p.view
    head = "".join(f"<th>{h}</th>" for h in ("channel", "unit", "n", "RMS before", "RMS after",
                                             "noise sigma (median)", "after / sigma"))
    body = []
    for r in p.rms:
        c = v.channels.index(r.channel)
        sigma = float(np.median(v.scale[v.channel == c]))
        ratio = f"{r.after / sigma:.3g}" if sigma > 0 else "–"
        cells = (r.channel, r.unit, r.n, f"{r.before:.4g}", f"{r.after:.4g}", f"{sigma:.3g}", ratio)
        body.append("<tr>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in cells) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def section(p: PhysicalResidual | None, png) -> str:  # type: ignore[no-untyped-def]
    """The report's HTML section (empty when the family cannot say its units)."""
    if p is None:
        return ""
    parts = ["<h2>Held-out fit in physical units</h2>",
             ("<p>The held-out residual of each channel in its unit (the whitened residual times "
             "the row's noise sigma); shaded: &plusmn; the noise sigma.</p>"), rms_table(p)]
    for title, img in (("Recorded and modelled", traces_plot(p, png)),
                       ("Residual before and after the fit", residual_plot(p, png))):
        if img:
            parts.append(f"<h3>{title}</h3><img src=\"data:image/png;base64,{img}\">")
    return "".join(parts)
