"""The calibration's outputs: ``calibration.yaml``, ``verdicts.json``, ``report.json``,
``report.html`` and the camera in OpenCV's form, ``opencv_intrinsics.yml``
(:func:`calibration.camera_forms.write_camera_form`).

The HTML page (a Jinja2 template, ``calibration/templates/report.html.j2``, in the project's one
environment: :func:`sim_core.html.jinja_environment`) lists every key's verdict
(:mod:`calibration.verdicts`: determined, not determined, unexplained, with its standard
deviation and reason), each procedure's result and residual next to its typical value
(docs/calibration.md), the views that were not used and why, and the residual plots
(matplotlib, written as PNG files beside it).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from calibration.camera_forms import OPENCV_FILE, write_camera_form
from calibration.verdicts import VERDICTS_FILE, count_line, write_verdicts
from sim_core.html import jinja_environment, number
from sim_core.twin_file import dump_yaml, twin_hash, write_calibration

#: typical residuals on this rig, for the summary (docs/calibration.md, "What each residual means")
TYPICAL = {
    "intrinsics": "reprojection RMS 0.05-0.3 px",
    "turntable": "axis 0.05-0.2 deg, point 0.5-2 mm, zero 0.02-0.1 deg",
    "depth": "board RMS 1-2 mm after (10-20 mm before)",
    "noise": "gain within 1-3 %, read noise within 5 %",
    "photometry": "white-square ratio spread 1-3 %",
    "solar": "scale within 1-3 %",
}


def _fmt(v: Any) -> str:
    """A provenance value in a summary cell: a float to four digits (as the operator page's
    calibration screen shows it), anything else as it is."""
    return number(v, "{:.4g}") if isinstance(v, float) else str(v)


def summary_rows(procedures: dict[str, dict]) -> list[dict[str, str]]:
    """One row per procedure: its main result and residual, from the provenance's summaries."""
    rows = []
    for name, d in procedures.items():
        if name == "views":
            continue
        result = ", ".join(f"{k} {_fmt(v)}" for k, v in d.items()
                           if not isinstance(v, (dict, list)) and "rms" not in k
                           and "residual" not in k)[:300]
        residual = ", ".join(f"{k} {_fmt(v)}" for k, v in d.items()
                             if ("rms" in k or "residual" in k)
                             and not isinstance(v, (dict, list)))[:200]
        rows.append({"procedure": name, "result": result, "residual": residual,
                     "typical": TYPICAL.get(name, "")})
    return rows


def _figures(out: Path, results: dict[str, Any]) -> list[dict[str, str]]:
    """Residual plots that the results carry (``plot(ax)`` methods), one PNG each."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figs = []
    for name, r in results.items():
        plot = getattr(r, "plot", None)
        if plot is None:
            continue
        fig, ax = plt.subplots(figsize=(6.0, 4.0), dpi=100)
        caption = plot(ax)
        fig.tight_layout()
        path = out / f"{name}.png"
        fig.savefig(path)
        plt.close(fig)
        figs.append({"file": path.name, "caption": caption or name})
    return figs


def write_report(out_dir: str | Path, result) -> dict[str, Path]:
    """Write the calibration and its report into ``out_dir`` (created); returns the paths.

    ``result`` is a :class:`calibration.rig_sequence.RigCalibration`.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=False)
    cal = result.calibration
    paths = {"calibration": write_calibration(out / "calibration.yaml", cal),
             "verdicts": write_verdicts(out / VERDICTS_FILE, result.verdicts),
             "opencv": write_camera_form(out / OPENCV_FILE, cal, "opencv")}
    prov = cal.provenance
    data = {
        "calibration_hash": twin_hash(cal),
        "calibration": cal.model_dump(mode="json", exclude={"provenance"}),
        "provenance": prov.model_dump(mode="json"),
    }
    paths["json"] = out / "report.json"
    paths["json"].write_text(json.dumps(data, indent=1, allow_nan=False), encoding="utf-8")
    rejected = list(prov.procedures.get("views", {}).get("not_detected", []))
    intr = prov.procedures.get("intrinsics", {})
    rejected += [r for r in intr.get("rejected", []) if isinstance(r, dict)]
    rejected += list(prov.procedures.get("views", {}).get("unexplained", []))
    html = jinja_environment("calibration").get_template("report.html.j2").render(
        rig=prov.rig, created_utc=prov.created_utc, software=prov.software,
        frames_used=prov.frames_used, calibration_hash=data["calibration_hash"],
        summary=summary_rows(prov.procedures), rejected=rejected,
        verdicts=result.verdicts, verdict_counts=count_line(result.verdicts),
        figures=_figures(out, result.results), calibration_yaml=dump_yaml(cal),
    )
    paths["html"] = out / "report.html"
    paths["html"].write_text(html, encoding="utf-8")
    return paths

