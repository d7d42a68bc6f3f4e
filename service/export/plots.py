"""A campaign's metrics over the poses as plots (matplotlib, SVG).

One table of plots (:data:`CAMPAIGN_PLOTS`, and :data:`EXPLAINED_PLOTS` for campaigns with an
object fit) serves the campaign report (inline SVG) and the operator page
(``GET /api/v1/campaigns/{id}/plots/{name}.svg``, reloaded as poses arrive). Each plot shows the
first repeat of every pose against the turntable angle; a missing or non-finite value is a gap.
"""

from __future__ import annotations

import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from service.export.results_table import EXPLAINED_TWINS
from sim_core.preview import MATPLOTLIB_LOCK

Row = dict[str, Any]
Value = Callable[[Row], float | None]


def _finite(v: Any) -> float | None:
    return float(v) if isinstance(v, int | float) and math.isfinite(v) else None


def metric(channel: str, name: str, scale: float = 1.0) -> Value:
    """The value ``metrics[channel][name]`` of a result row (times ``scale``), or None."""
    def get(row: Row) -> float | None:
        v = _finite((row["metrics"].get(channel) or {}).get(name))
        return None if v is None else v * scale
    return get


def explained(twin: str, name: str, scale: float = 1.0) -> Value:
    """The value ``metrics["explained"][twin][name]`` (times ``scale``), or None."""
    def get(row: Row) -> float | None:
        v = _finite(((row["metrics"].get("explained") or {}).get(twin) or {}).get(name))
        return None if v is None else v * scale
    return get


@dataclass(frozen=True)
class PlotSpec:
    """A plot: its title (with the unit) and its series (label, value of a row)."""

    name: str
    title: str
    series: tuple[tuple[str, Value], ...]


CAMPAIGN_PLOTS = (
    PlotSpec("depth-difference", "Depth sim - meas [mm]", (
        ("median", metric("tof", "depth_diff_median_mm")),
        ("MAD", metric("tof", "depth_diff_mad_mm")),
        ("95 % of |diff|", metric("tof", "depth_diff_p95_abs_mm")))),
    PlotSpec("pixel-shares", "Flying and invalid pixels [% of mask]", (
        ("flying, measured", metric("tof", "flying_share_measured", 100.0)),
        ("flying, simulated", metric("tof", "flying_share_simulated", 100.0)),
        ("invalid, measured", metric("tof", "invalid_share_measured", 100.0)),
        ("invalid, simulated", metric("tof", "invalid_share_simulated", 100.0)))),
    PlotSpec("ssim", "SSIM", (("grey", metric("grey", "ssim")),
                              ("depth", metric("depth", "ssim")))),
    PlotSpec("psnr", "PSNR [dB]", (("grey", metric("grey", "psnr_db")),
                                   ("depth", metric("depth", "psnr_db")))),
    PlotSpec("depth-mean", "Mean depth [mm]", (("measured", metric("depth", "mean_measured")),
                                               ("simulated", metric("depth", "mean_simulated")))),
    PlotSpec("grey-mean", "Mean grey [level]", (("measured", metric("grey", "mean_measured")),
                                                ("simulated", metric("grey", "mean_simulated")))),
)
EXPLAINED_PLOTS = (
    PlotSpec("explained-depth-rmse", "Depth RMSE [mm]",
             tuple((t, explained(t, "depth_rmse_m", 1e3)) for t in EXPLAINED_TWINS)),
    PlotSpec("explained-grey-psnr", "Grey PSNR [dB]",
             tuple((t, explained(t, "grey_psnr_db")) for t in EXPLAINED_TWINS)),
)
PLOTS = {p.name: p for p in (*CAMPAIGN_PLOTS, *EXPLAINED_PLOTS)}


def plot_svg(spec: PlotSpec, rows: Sequence[Row], width_in: float = 4.4,
             height_in: float = 2.5) -> str:
    """The plot of ``spec`` over ``rows`` (first repeats, in pose order) as an ``<svg>`` element
    (no XML prologue: it can be inlined in HTML or served as a file)."""
    import matplotlib
    from matplotlib.backends.backend_svg import FigureCanvasSVG
    from matplotlib.figure import Figure

    x = [float(r["turntable_deg"]) for r in rows]
    svg_text = {"svg.fonttype": "none", "svg.hashsalt": spec.name}  # text as text, stable ids
    with MATPLOTLIB_LOCK, matplotlib.rc_context(svg_text):
        fig = Figure(figsize=(width_in, height_in), dpi=100, layout="constrained")
        FigureCanvasSVG(fig)
        ax = fig.add_subplot()
        ax.set_title(spec.title, fontsize=10)
        ax.set_xlabel("turntable angle [deg]", fontsize=9)
        ax.tick_params(labelsize=8)
        ax.ticklabel_format(axis="y", useOffset=False)  # plain values in the title's unit
        ax.grid(True, alpha=0.3)
        drawn = False
        for label, value in spec.series:
            y = [value(r) for r in rows]
            ys = [math.nan if v is None else v for v in y]
            if any(v is not None for v in y):
                drawn = True
            ax.plot(x, ys, marker="o", markersize=3, linewidth=1.3, label=label)
        if drawn:
            ax.legend(fontsize=8, loc="best")
        else:
            ax.text(0.5, 0.5, "no data yet", ha="center", va="center", transform=ax.transAxes,
                    fontsize=9, color="#666")
        buf = io.StringIO()
        fig.savefig(buf, format="svg")
    text = buf.getvalue()
    return text[text.index("<svg"):]
