"""Issue 27's sweep: the object fit's verdicts on random realities with every effect of the world.

Each seed draws a reality of the simulated lab (camera, rig and object as in
:func:`tests.calibration.realities.random_reality`, plus the warm-up drift, the stray light and
the table's settling of :func:`~tests.calibration.realities.with_world_effects`) and a random set
of 3-6 distinct angles in -90..90 deg, runs ``toftwin fit-object --simulated`` (the stage moving
in real time: ``TOFTWIN_SIM_MOTION=real``) with the rig's
perfect calibration (the reality's camera and rig keys, effects included, never its object keys)
and tabulates, for every key the fit reports, its verdict, its error against the reality and
``|error| / std``. A key ``determined`` beyond 3 std whose error is also beyond its target is a
confident wrong number: the sweep names it and exits 1.

Not a test (each seed takes minutes): a command, ``python -m tests.calibration.verdict_sweep
--seeds 201-220 --out DIR``; a seed whose ``DIR/<seed>/summary.json`` exists is not run again.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from sim_core.scene_spec import load_scene_spec
from tests.calibration.realities import (
    perfect_calibration,
    random_reality,
    sweep_main,
    with_world_effects,
)
from tests.sim_core.scenes import EXAMPLES

SPEC = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
MOUNTED = [o.name for o in SPEC.objects if o.on_turntable]
#: issue 14's targets, per component: position [m], rotation [deg], reflectance scale (relative:
#: 3 % of the true scale)
TARGETS = {"mount.pose_offset.position_m": 0.001, "mount.pose_offset.rotation_deg": 0.2,
           "reflectance_scale": 0.03}
#: beyond this many standard deviations a determined key must be within its target
Z_LIMIT = 3.0


def random_angles(seed: int) -> list[float]:
    """3-6 distinct whole-degree angles in -90..90, sorted (a stream of their own)."""
    rng = np.random.default_rng([seed, 2700])
    n = int(rng.integers(3, 7))
    return sorted(float(a) for a in rng.choice(np.arange(-90, 91), size=n, replace=False))


def run_seed(seed: int, out: Path, toftwin: str) -> dict:
    """Fit one seed's reality (module docstring); its summary (also ``out/summary.json``)."""
    reality = with_world_effects(
        random_reality(seed, nominal_power_w=SPEC.illumination.power_w,
                       object_twin_names=MOUNTED), seed)
    angles = random_angles(seed)
    out.mkdir(parents=True, exist_ok=True)
    (out / "reality.yaml").write_text(yaml.safe_dump(reality.model_dump(mode="json")))
    (out / "calibration.yaml").write_text(
        yaml.safe_dump(perfect_calibration(reality).model_dump(mode="json")))
    t0 = time.time()
    fit_dir = out / "fit"
    res = subprocess.run(
        [toftwin, "fit-object", "--simulated", "--reality", str(out / "reality.yaml"),
         "--calibration", str(out / "calibration.yaml"),
         "--angles", ",".join(f"{a:g}" for a in angles), "--frames", "32",
         "--camera-spp", "64", "--seed", str(seed), "--out", str(fit_dir)],
        capture_output=True, text=True, check=False,
        # the stage moves in real time, so the table rings after each move (an instant stage
        # has settled at once) and the service waits the calibrated settling out
        env={**os.environ, "TOFTWIN_SIM_MOTION": "real"})
    summary: dict = {"seed": seed, "angles": angles, "seconds": round(time.time() - t0, 1),
                     "returncode": res.returncode, "rows": []}
    if res.returncode:
        summary["refused"] = (res.stderr or res.stdout).strip().splitlines()[-1:]
    else:
        summary.update(_rows(reality.model_dump(mode="json"), fit_dir))
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def _rows(truth: dict, fit_dir: Path) -> dict:
    verdicts = json.loads((fit_dir / "verdicts.json").read_text())
    fitted = yaml.safe_load((fit_dir / "object.yaml").read_text())
    report = json.loads((fit_dir / "object-report.json").read_text())
    rows = []

    def row(key: str, estimate, true, target: float) -> None:
        v = verdicts[key]
        err = np.atleast_1d(np.subtract(estimate, true)).astype(float)
        std = np.atleast_1d(np.nan if v["std"] is None else v["std"]).astype(float)
        z = np.abs(err) / std
        rows.append({"key": key, "verdict": v["verdict"], "error": err.tolist(),
                     "std": std.tolist(), "z": [None if not math.isfinite(x) else x for x in z],
                     "target": target, "reason": v["reason"]})

    if "mount" in fitted:
        pose, true_pose = fitted["mount"]["pose_offset"], truth["mount"]["pose_offset"]
        for field in ("position_m", "rotation_deg"):
            key = f"mount.pose_offset.{field}"
            row(key, pose[field], true_pose[field], TARGETS[key])
    for name, entry in report["objects"].items():
        true = truth["objects"][name]["reflectance_scale"]
        row(f"objects.{name}.reflectance_scale", entry["reflectance_scale"], true,
            TARGETS["reflectance_scale"] * true)
    refined = report["refined"]
    return {"rows": rows, "reduced_chi2": refined.get("reduced_chi2_after"),
            "dropped_views": [d["turntable_angle_deg"] for d in report.get("dropped_views", [])]}


def confident_wrong(row: dict) -> bool:
    """A determined key beyond :data:`Z_LIMIT` std whose error is also beyond its target."""
    if row["verdict"] != "determined":
        return False
    return any(z is not None and z > Z_LIMIT and abs(e) > row["target"]
               for z, e in zip(row["z"], row["error"], strict=True))


def table(summaries: list[dict]) -> str:
    """The sweep as a markdown table: one line per seed."""
    lines = ["| seed | angles [deg] | chi2 | determined / not / unexplained | largest "
             "\\|err\\|/std of a determined key (its error; target) | confident wrong |",
             "|---|---|---|---|---|---|"]
    for s in summaries:
        angles = ",".join(f"{a:g}" for a in s["angles"])
        if s.get("refused"):
            lines.append(f"| {s['seed']} | {angles} | - | refused: {s['refused'][0][:90]} | - "
                         "| - |")
            continue
        counts = [sum(r["verdict"] == v for r in s["rows"])
                  for v in ("determined", "not determined", "unexplained")]
        worst, text = -1.0, "-"
        for r in s["rows"]:
            if r["verdict"] != "determined":
                continue
            for z, e in zip(r["z"], r["error"], strict=True):
                if z is not None and z > worst:
                    worst = z
                    text = f"{z:.2f} {r['key']} ({e:.3g}; {r['target']:g})"
        wrong = [r["key"] for r in s["rows"] if confident_wrong(r)]
        chi2 = s.get("reduced_chi2")
        dropped = f" (dropped {s['dropped_views']})" if s.get("dropped_views") else ""
        lines.append(f"| {s['seed']} | {angles} | "
                     f"{'-' if chi2 is None else f'{chi2:.2f}'}{dropped} | "
                     f"{counts[0]} / {counts[1]} / {counts[2]} | {text} | "
                     f"{', '.join(wrong) or 'none'} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    def toftwin_argument(parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--toftwin", default=str(Path(sys.executable).with_name("toftwin")))

    return sweep_main(argv, __doc__.splitlines()[0], table, confident_wrong,
                      lambda args: lambda seed, out: run_seed(seed, out, args.toftwin),
                      toftwin_argument)

if __name__ == "__main__":
    raise SystemExit(main())
