"""The HTML report of a campaign: metrics over the poses, and image panels per pose.

Self-contained: plots are inline SVG, images inline PNG data URIs, so the page can be saved
and mailed. Per pose (its first repeat) six panels: grey measured / simulated / |difference|
(grey levels, each frame's grey image at its own grey full scale: its grey.png, as in the
metrics; :func:`sim_core.frame_io.grey_full_scale`), and depth measured /
simulated (near yellow, far blue) / difference (simulated - measured, red = farther, +-50 mm).
"""

from __future__ import annotations

import base64
import html
import io
import json
from typing import Any

import numpy as np
from PIL import Image
from sqlalchemy.orm import sessionmaker

from service.errors import GoneError
from service.export.results_table import result_rows
from service.store import queries
from service.store.frame_files import FrameStore
from sim_core import frame_io
from sim_core.frame_io import Frame
from sim_core.preview import depth_colours

#: poses with image panels (the plots show every pose)
MAX_PANEL_POSES = 60
DEPTH_DIFF_RANGE_MM = 50.0

_PLOTS = (
    ("SSIM", (("grey", "grey", "ssim"), ("depth", "depth", "ssim"))),
    ("PSNR [dB]", (("grey", "grey", "psnr_db"), ("depth", "depth", "psnr_db"))),
    ("Mean depth [mm]", (("measured", "depth", "mean_measured"),
                         ("simulated", "depth", "mean_simulated"))),
    ("Mean grey [level]", (("measured", "grey", "mean_measured"),
                           ("simulated", "grey", "mean_simulated"))),
)
_COLOURS = ("#1f77b4", "#d62728", "#2ca02c")


def _png(rgb: np.ndarray) -> str:
    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, format="PNG", optimize=True)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def _load(store: FrameStore, frame_id: str) -> Frame:
    store.file(frame_id, frame_io.FRAME_NPZ)  # GoneError naming the frame if it is lost
    return frame_io.read_frame(store.path(frame_id))


def _rgb(grey: np.ndarray) -> np.ndarray:
    return np.repeat(grey[..., None], 3, axis=2)


def _diverging(diff_mm: np.ndarray, valid: np.ndarray) -> np.ndarray:
    t = np.clip(np.nan_to_num(diff_mm) / DEPTH_DIFF_RANGE_MM, -1.0, 1.0)
    rgb = np.full((*t.shape, 3), 255.0)
    rgb[..., 0] -= np.where(t < 0, -t, 0.0) * 255.0  # blue: nearer than measured
    rgb[..., 1] -= np.abs(t) * 255.0
    rgb[..., 2] -= np.where(t > 0, t, 0.0) * 255.0  # red: farther
    rgb[~valid] = 0.0
    return rgb.astype(np.uint8)


def pose_panels(store: FrameStore, measured_id: str, simulated_id: str) -> list:
    """Six (caption, data URI) panels for one pose."""
    mf, sf = _load(store, measured_id), _load(store, simulated_id)
    m = {"range_m": mf.image.range_m, "valid": mf.image.valid}
    s = {"range_m": sf.image.range_m, "valid": sf.image.valid}
    gm, gs = _rgb(mf.grey_8bit()), _rgb(sf.grey_8bit())
    both = m["valid"] & s["valid"]
    gdiff = np.abs(gm.astype(int) - gs.astype(int)).astype(np.uint8)
    gdiff[~both] = 0
    ddiff = (s["range_m"] - m["range_m"]) * 1000.0
    return [
        ("grey measured", _png(gm)), ("grey simulated", _png(gs)),
        ("|grey difference|", _png(gdiff)),
        ("depth measured", _png(depth_colours(m["range_m"], m["valid"]))),
        ("depth simulated", _png(depth_colours(s["range_m"], s["valid"]))),
        (f"depth sim - meas (+-{DEPTH_DIFF_RANGE_MM:g} mm)", _png(_diverging(ddiff, both))),
    ]


def svg_plot(title: str, x: list[float], series: list[tuple[str, list[float | None]]],
             width: int = 420, height: int = 220) -> str:
    """A small line plot (points joined in order; None/non-finite values are gaps)."""
    pad_l, pad_r, pad_t, pad_b = 56, 10, 24, 34
    ys = [v for _, vals in series for v in vals if isinstance(v, float | int)
          and np.isfinite(v)]
    if not x or not ys:
        return f"<p>{html.escape(title)}: no data</p>"
    x0, x1 = min(x), max(x)
    y0, y1 = min(ys), max(ys)
    if x1 == x0:
        x0, x1 = x0 - 1, x1 + 1
    if y1 == y0:
        y0, y1 = y0 - 1, y1 + 1

    def px(v: float) -> float:
        return pad_l + (v - x0) / (x1 - x0) * (width - pad_l - pad_r)

    def py(v: float) -> float:
        return height - pad_b - (v - y0) / (y1 - y0) * (height - pad_t - pad_b)

    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
             f'role="img" aria-label="{html.escape(title)}">',
             f'<text x="{width / 2}" y="15" text-anchor="middle" font-size="13">'
             f"{html.escape(title)}</text>",
             f'<rect x="{pad_l}" y="{pad_t}" width="{width - pad_l - pad_r}" '
             f'height="{height - pad_t - pad_b}" fill="none" stroke="#999"/>']
    for v in (y0, (y0 + y1) / 2, y1):
        parts.append(f'<text x="{pad_l - 4}" y="{py(v) + 4:.1f}" text-anchor="end" '
                     f'font-size="10">{v:.4g}</text>')
    for v in (x0, x1):
        parts.append(f'<text x="{px(v):.1f}" y="{height - pad_b + 14}" text-anchor="middle" '
                     f'font-size="10">{v:.4g}</text>')
    parts.append(f'<text x="{width / 2}" y="{height - 4}" text-anchor="middle" '
                 'font-size="11">turntable angle [deg]</text>')
    for k, (label, vals) in enumerate(series):
        colour = _COLOURS[k % len(_COLOURS)]
        pts = [(px(a), py(b)) for a, b in zip(x, vals, strict=True)
               if isinstance(b, float | int) and np.isfinite(b)]
        path = " ".join(f"{a:.1f},{b:.1f}" for a, b in pts)
        parts.append(f'<polyline points="{path}" fill="none" stroke="{colour}" '
                     'stroke-width="1.5"/>')
        parts += [f'<circle cx="{a:.1f}" cy="{b:.1f}" r="2.5" fill="{colour}"/>'
                  for a, b in pts]
        parts.append(f'<text x="{pad_l + 6}" y="{pad_t + 14 + 13 * k}" font-size="11" '
                     f'fill="{colour}">{html.escape(label)}</text>')
    parts.append("</svg>")
    return "".join(parts)


def _metric(row: dict[str, Any], ch: str, name: str) -> float | None:
    v = (row["metrics"].get(ch) or {}).get(name)
    return float(v) if isinstance(v, int | float) and np.isfinite(v) else None


def _explained(row: dict[str, Any], twin: str, name: str) -> float | None:
    v = ((row["metrics"].get("explained") or {}).get(twin) or {}).get(name)
    return float(v) if isinstance(v, int | float) and np.isfinite(v) else None


def _median(values: list[float | None]) -> float | None:
    vals = [v for v in values if v is not None]
    return float(np.median(vals)) if vals else None


def _cell(value: float | None, scale: float = 1.0, fmt: str = "{:.2f}") -> str:
    return "-" if value is None else fmt.format(value * scale)


def explained_section(camp: Any, first: list[dict[str, Any]]) -> list[str]:
    """The explained difference of a campaign with an object fit (issue 14, section 4): the
    fitted object twin, then per pose the depth RMSE and grey PSNR against the nominal twin,
    the fitted twin and the noise ceiling (two captures of the same state), with their medians.
    """
    esc = html.escape
    out = ["<h2>Explained difference (object twin)</h2>"]
    if camp.object_twin_json is None:
        return [*out, "<p>The object fit has not run yet.</p>"]
    twin = json.loads(camp.object_twin_json)
    report = json.loads(camp.object_fit_report_json or "{}")
    off = (twin.get("mount") or {}).get("pose_offset") or {}
    scales = {k: v.get("reflectance_scale") for k, v in (twin.get("objects") or {}).items()}
    out.append(
        f"<p>Fitted mount offset: position {esc(str(off.get('position_m')))} m, rotation "
        f"{esc(str(off.get('rotation_deg')))} deg; reflectance scales {esc(str(scales))}.</p>"
        f"<details><summary>Fit report</summary><pre>"
        f"{esc(json.dumps(report, indent=1)[:20000])}</pre></details>")
    x = [r["turntable_deg"] for r in first]
    twins = ("nominal", "fitted", "ceiling")
    out.append("<div class='plots'>" + svg_plot(
        "Depth RMSE [mm]", x, [(t, [None if (v := _explained(r, t, "depth_rmse_m")) is None
                                    else v * 1e3 for r in first]) for t in twins])
        + svg_plot("Grey PSNR [dB]", x, [(t, [_explained(r, t, "grey_psnr_db") for r in first])
                                         for t in twins]) + "</div>")
    head = ("pose", "angle [deg]", "depth RMSE nominal [mm]", "fitted [mm]", "ceiling [mm]",
            "grey PSNR nominal [dB]", "fitted [dB]", "ceiling [dB]", "explained depth",
            "explained grey")
    rows = []
    for r in first:
        ex = (r["metrics"].get("explained") or {}).get("explained") or {}
        rows.append((str(r["pose_index"]), f"{r['turntable_deg']:g}",
                     *(_cell(_explained(r, t, "depth_rmse_m"), 1e3) for t in twins),
                     *(_cell(_explained(r, t, "grey_psnr_db")) for t in twins),
                     *(_cell(ex.get(ch), 100.0, "{:.0f} %") for ch in ("depth", "grey"))))
    rows.append(("median", "",
                 *(_cell(_median([_explained(r, t, "depth_rmse_m") for r in first]), 1e3)
                   for t in twins),
                 *(_cell(_median([_explained(r, t, "grey_psnr_db") for r in first]))
                   for t in twins), "", ""))
    out.append("<table><tr>" + "".join(f"<th>{esc(h)}</th>" for h in head) + "</tr>"
               + "".join("<tr>" + "".join(f"<td>{esc(c)}</td>" for c in row) + "</tr>"
                         for row in rows) + "</table>")
    out.append("<p>Nominal: the campaign's calibration with the scene's object as designed; "
               "fitted: the same calibration with the fitted object twin; ceiling: a second "
               "capture of the same state (what no twin can beat). 'Explained' is the share "
               "of the nominal twin's excess MSE over the ceiling that the fit removes; what "
               "is left is model error.</p>")
    return out


def campaign_report(sessions: sessionmaker, store: FrameStore, campaign_id: str) -> str:
    """The whole HTML page."""
    with sessions() as s:
        camp = queries.require_campaign(s, campaign_id)
    rows = result_rows(sessions, campaign_id)
    first = [r for r in rows if r["repeat"] == 0]
    x = [r["turntable_deg"] for r in first]
    plots = [svg_plot(title, x, [(label, [_metric(r, ch, name) for r in first])
                                 for label, ch, name in keys])
             for title, keys in _PLOTS]
    esc = html.escape
    base = f"/api/v1/campaigns/{campaign_id}"
    out = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>Campaign {esc(camp.name)}</title>",
        "<style>body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse}"
        "td,th{border:1px solid #ccc;padding:4px;font-size:12px;text-align:center}"
        "img{image-rendering:pixelated;width:224px}.plots svg{margin:4px}</style>",
        "</head><body>",
        f"<h1>Campaign {esc(camp.name)}</h1>",
        f"<p>id {esc(camp.id)} &middot; scene <b>{esc(camp.scene_name)}</b> &middot; state "
        f"<b>{esc(camp.state)}</b> &middot; {len(rows)} of {camp.poses_total} pose "
        f"measurements &middot; seed {camp.seed}, {camp.spp} spp</p>",
        f"<p><a href='{base}/results'>results (JSON)</a> &middot; "
        f"<a href='{base}/results?format=csv'>results (CSV)</a> &middot; "
        f"<a href='{base}/documents'>Bluesky documents</a></p>",
        "<h2>Metrics over the poses (first repeat)</h2><div class='plots'>",
        *plots, "</div>",
    ]
    if camp.object_fit_json is not None:
        out += explained_section(camp, first)
    out.append("<h2>Poses</h2>")
    if len(first) > MAX_PANEL_POSES:
        out.append(f"<p>Image panels of the first {MAX_PANEL_POSES} poses only.</p>")
    for r in first[:MAX_PANEL_POSES]:
        table = json.dumps({k: _metric(r, k, "ssim") for k in ("grey", "depth")})
        out.append(
            f"<h3>Pose {r['pose_index']}: {r['turntable_deg']:g} deg, {r['solar_suns']:g} sun"
            f"</h3><p>SSIM {esc(table)}; error: {esc(str(r['metrics'].get('error') or '-'))}"
            "</p>"
        )
        try:
            panels = pose_panels(store, r["measured_frame_id"], r["simulated_frame_id"])
        except (GoneError, OSError) as exc:  # one lost frame folder leaves a gap, not a 500
            out.append(f"<p class='gap'>No images: {esc(str(exc))}</p>")
            continue
        out.append(
            "<table><tr>" + "".join(f"<th>{esc(c)}</th>" for c, _ in panels) + "</tr><tr>"
            + "".join(f"<td><img alt='{esc(c)}' src='{u}'></td>" for c, u in panels)
            + "</tr></table>"
        )
    out.append("</body></html>")
    return "\n".join(out)
