"""``toftwin bench mitsuba``: our renderer against Mitsuba 3 on the ``corner`` scene.

The same scene, camera, light and material are rendered by our path tracer (``dc_active`` of
:func:`sim_core.render.render`) and by Mitsuba 3's ``path`` integrator (variant ``llvm_ad_mono``,
its LLVM backend on all cores), and the benchmark reports:

1. seconds per frame of each and their ratio (ours / Mitsuba) at equal samples per pixel and
   bounces, both warm: Mitsuba's first render of each setting (kernel compilation by Dr.Jit) is
   timed separately and left out, and our numba kernels are compiled by a warm-up render. Each
   figure is the best of a few interleaved repeats, which is robust to other load on the machine;
2. the agreement of the two DC images after one global scale factor fitted by least squares
   (``ours ~ scale * mitsuba``, fitted on 8 x 8 pixel block means so that pixel noise does not bias
   it; 1 when the units match): relative RMSE, max relative error over pixels, and the relative
   RMSE of the block means, which averages most Monte Carlo noise away and so shows a bias if
   there is one;
3. a convergence comparison: a high-spp reference rendered by us, first checked against a
   high-spp Mitsuba reference, then both renderers swept over spp and the time each needs to
   reach a target relative RMSE against that reference, interpolated in log-log.

How the scene is matched in Mitsuba (and what differs): :mod:`sim_core.mitsuba_scene`, the
converter ``toftwin export mitsuba`` writes its files with (here its ``load_dict`` form); how
Mitsuba is loaded (its LLVM backend proven in a child process first):
:mod:`benchmarks.renderer.mitsuba_backend`. Mitsuba is a benchmark dependency only (extra
``bench``), imported lazily, so the CLI works without it.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from benchmarks.renderer.mitsuba_backend import MITSUBA_VARIANT, load_mitsuba
from sim_core.mitsuba_scene import (
    MitsubaIntegrator,
    camera_mismatch_deg,
    describe_scene,
    integrator_dict,
    scene_dict,
)
from sim_core.render import RenderSettings, render
from sim_core.scene import Scene, build_scene
from sim_core.scene_spec import EXAMPLES_DIR, load_scene_spec
from sim_core.tracing import RayTracer

CORNER_SCENE = EXAMPLES_DIR / "corner.yaml"


@dataclass(frozen=True)
class _Plan:
    """Sizes of one benchmark run."""

    spps: tuple[int, ...]
    bounces: tuple[int, ...]
    repeats: int
    reference_spp: int
    reference_bounces: int
    sweep_spps: tuple[int, ...]
    target_rel_rmse: float


#: block size of the noise-suppressing comparison [px]
BLOCK_PX = 8
#: pixels darker than this fraction of the brightest are left out of the max relative error
MAX_REL_FLOOR = 1e-3


# -------------------------------------------------------------------------------------------
# Image comparison
# -------------------------------------------------------------------------------------------
def fit_scale(ours: np.ndarray, theirs: np.ndarray) -> float:
    """Least-squares ``s`` minimising ``sum (ours - s * theirs)^2``."""
    den = float(np.sum(theirs * theirs))
    return float(np.sum(ours * theirs) / den) if den > 0.0 else float("nan")


def rel_rmse(img: np.ndarray, ref: np.ndarray) -> float:
    """``||img - ref|| / ||ref||`` over all pixels (RMS error relative to the RMS signal)."""
    den = float(np.sqrt(np.sum(ref * ref)))
    return float(np.sqrt(np.sum((img - ref) ** 2)) / den) if den > 0.0 else float("nan")


def block_means(img: np.ndarray, k: int = BLOCK_PX) -> np.ndarray:
    """Means of ``k x k`` pixel blocks (rows and columns beyond a multiple of k dropped)."""
    h, w = (img.shape[0] // k) * k, (img.shape[1] // k) * k
    return img[:h, :w].reshape(h // k, k, w // k, k).mean(axis=(1, 3))


def agreement(ours: np.ndarray, theirs: np.ndarray) -> dict:
    """Scale fit of ``theirs`` onto ``ours`` and the residual errors (relative to ours).

    The scale is the least-squares fit on :func:`block_means` of the images: fitted on single
    noisy pixels it would come out low by about the squared relative noise (noise in the
    regressor, "attenuation bias": 1.3 % at 16 % per-pixel noise), which is not a unit mismatch.
    """
    s = fit_scale(block_means(ours), block_means(theirs))
    fitted = s * theirs
    floor = MAX_REL_FLOOR * float(np.max(ours)) if ours.size else 0.0
    lit = ours > floor
    max_rel = (
        float(np.max(np.abs(ours[lit] - fitted[lit]) / ours[lit])) if lit.any() else float("nan")
    )
    return {
        "scale": s,
        "rel_rmse": rel_rmse(fitted, ours),
        "max_rel_err": max_rel,
        "rel_rmse_blocks": rel_rmse(block_means(fitted), block_means(ours)),
    }


def loglog_crossing(x, y, target: float) -> tuple[float, bool]:
    """``x`` at which the decreasing ``y(x)`` reaches ``target``, interpolated in log-log.

    Between the two sweep points that bracket ``target`` it interpolates; otherwise it
    extrapolates the least-squares line through all points (second value True). NaN if ``y``
    does not decrease with ``x``.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    ok = (x > 0) & (y > 0) & np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size == 0 or not target > 0:
        return float("nan"), True
    order = np.argsort(x)
    lx, ly, lt = np.log(x[order]), np.log(y[order]), math.log(target)
    for i in range(lx.size - 1):
        y0, y1 = ly[i], ly[i + 1]
        if y0 >= lt >= y1 and y0 > y1:
            f = (y0 - lt) / (y0 - y1)
            return float(np.exp(lx[i] + f * (lx[i + 1] - lx[i]))), False
    if lx.size < 2 or np.ptp(lx) == 0.0:
        return float("nan"), True
    slope, icpt = np.polyfit(lx, ly, 1)
    if not slope < 0.0:
        return float("nan"), True
    return float(np.exp((lt - icpt) / slope)), True


# -------------------------------------------------------------------------------------------
# The two renderers behind one interface
# -------------------------------------------------------------------------------------------
class _Ours:
    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.tracer = RayTracer(scene.triangles_m, scene.camera.position_m)
        self.rr = RenderSettings().russian_roulette_from_bounce

    def settings(self, spp: int, bounces: int, seed: int) -> RenderSettings:
        return RenderSettings(
            integrator="direct" if bounces == 1 else "path",
            spp=spp, max_bounces=bounces, seed=seed, ambient=False,
        )

    def render(self, spp: int, bounces: int, seed: int):
        """(dc_active image, per-pixel variance of the mean, seconds)."""
        t0 = time.perf_counter()
        res = render(self.scene, self.settings(spp, bounces, seed), self.tracer)
        dt = time.perf_counter() - t0
        lf = res.light_field
        return lf.dc_active, lf.dc_active_var / spp, dt

    def close(self) -> None:
        self.tracer.close()


class _Mitsuba:
    def __init__(self, mi, scene: Scene, rr_from_bounce: int) -> None:
        self.mi = mi
        desc = describe_scene(scene, rr_from_bounce=rr_from_bounce)
        with tempfile.TemporaryDirectory(prefix="toftwin-mitsuba-") as tmp:
            self.scene = mi.load_dict(scene_dict(mi, desc, Path(tmp)))
        self.rr = rr_from_bounce
        self.integrators: dict[int, object] = {}

    def integrator(self, bounces: int):
        if bounces not in self.integrators:
            self.integrators[bounces] = self.mi.load_dict(
                integrator_dict(MitsubaIntegrator.matching(bounces, self.rr)))
        return self.integrators[bounces]

    def render(self, spp: int, bounces: int, seed: int):
        """(radiance image float64, seconds); the readback forces the lazy evaluation."""
        integ = self.integrator(bounces)
        t0 = time.perf_counter()
        img = np.asarray(self.mi.render(self.scene, integrator=integ, spp=int(spp), seed=seed))
        dt = time.perf_counter() - t0
        return img.reshape(img.shape[0], img.shape[1], -1)[..., 0].astype(np.float64), dt


# -------------------------------------------------------------------------------------------
# The benchmark
# -------------------------------------------------------------------------------------------
def _plan(spps, bounces, quick: bool, target, reference_spp, repeats) -> _Plan:
    spps = tuple(sorted({int(s) for s in spps}))
    bounces = tuple(sorted({int(b) for b in bounces}))
    if not spps or spps[0] < 1:
        raise ValueError(f"spps must be positive integers, got {spps}")
    if not bounces or bounces[0] < 1:
        raise ValueError(f"bounces must be integers >= 1, got {bounces}")
    if quick:
        spps = tuple(sorted({min(s, 4) for s in spps}))
        bounces = tuple(sorted({min(b, 2) for b in bounces}))
    ref_b = max(bounces)
    return _Plan(
        spps=spps,
        bounces=bounces,
        repeats=int(repeats or (1 if quick else 3)),
        reference_spp=int(reference_spp or (64 if quick else 2048)),
        reference_bounces=ref_b,
        sweep_spps=(1, 2, 4, 8) if quick else (16, 32, 64, 128, 256, 512),
        target_rel_rmse=float(target or (0.10 if quick else 0.02)),
    )


def _fmt(x: float, spec: str = ".3f") -> str:
    return "-" if x is None or not np.isfinite(x) else format(x, spec)


def run_mitsuba_comparison(
    console: Console,
    spps=(16, 64, 256),
    bounces=(1, 2, 3),
    quick: bool = False,
    *,
    target_rel_rmse: float | None = None,
    reference_spp: int | None = None,
    repeats: int | None = None,
    convergence: bool = True,
) -> dict:
    """Render ``corner`` in our renderer and in Mitsuba 3; print and return the comparison.

    Parameters
    ----------
    console : rich Console
    spps, bounces : iterables of int
        Samples per pixel and bounce counts of the speed and agreement table (direct = 1).
    quick : bool
        Smoke run: spp capped at 4, bounces at 2, one repeat, a 64-spp reference, a sweep over
        1-8 spp and a 10 % target (the default is a 2048-spp reference, 16-512 spp, 2 %).
    target_rel_rmse, reference_spp, repeats : optional overrides of those choices.
    convergence : bool
        Whether to run parts 2 and 3 (the high-spp reference check and the time to the target
        error); without them the run is the speed table alone and ``reference`` and
        ``time_to_error`` are None.

    Returns
    -------
    dict with ``rows`` (one per spp and bounce count), ``reference`` (the high-spp check),
    ``time_to_error`` (sweeps and the interpolated times) and the setup (versions, threads,
    camera check, our tracer's backend and packet widths). Each row has ``spp``, ``bounces``,
    ``ours_s``, ``mitsuba_s`` and ``ratio_ours_over_mitsuba`` (best of the repeats, warm).

    Raises
    ------
    RuntimeError
        If Mitsuba or its LLVM backend cannot be loaded (the message says how to install them).
    """
    mi, dr, llvm_path = load_mitsuba()
    plan = _plan(spps, bounces, quick, target_rel_rmse, reference_spp, repeats)
    load_before = os.getloadavg()
    spec = load_scene_spec(CORNER_SCENE)
    scene = build_scene(spec, base_dir=CORNER_SCENE.parent)
    ours = _Ours(scene)
    try:
        theirs = _Mitsuba(mi, scene, ours.rr)
        cam_deg = camera_mismatch_deg(mi, theirs.scene, scene)
        intr = scene.camera.intrinsics
        setup = {
            "scene": spec.name,
            "resolution": (intr.width_px, intr.height_px),
            "triangles": scene.n_triangles,
            "light_power_w": float(scene.light.power_w),
            "mitsuba_version": getattr(mi, "__version__", "?"),
            "drjit_version": getattr(dr, "__version__", "?"),
            "variant": MITSUBA_VARIANT,
            "libllvm": llvm_path,
            "threads_ours": ours.tracer.threads,
            "tracer_backend": ours.tracer.backend,
            "packet_widths_camera_bounce_shadow": ours.tracer.widths,
            "threads_mitsuba": int(dr.thread_count()),
            "camera_mismatch_deg": cam_deg,
            "repeats": plan.repeats,
            "quick": quick,
        }
        console.print(
            f"{spec.name}: {scene.n_triangles} triangles, {intr.width_px} x "
            f"{intr.height_px} px, light {scene.light.power_w:g} W | Mitsuba "
            f"{setup['mitsuba_version']} ({MITSUBA_VARIANT}, Dr.Jit {setup['drjit_version']}, "
            f"{setup['threads_mitsuba']} threads, libLLVM {llvm_path or 'found by Dr.Jit'}) | "
            f"ours {setup['threads_ours']} threads, Embree via {ours.tracer.backend} | camera "
            f"rays differ by <= {cam_deg:.1e} deg"
        )
        rows = _speed_and_agreement(console, ours, theirs, plan)
        reference = tte = None
        if convergence:
            reference = _reference_check(console, ours, theirs, plan)
            tte = _time_to_error(console, ours, theirs, plan, reference)
            reference.pop("_image", None)
            reference.pop("_var", None)
    finally:
        ours.close()
    load_after = os.getloadavg()
    setup["load_avg_1min_before_after"] = (load_before[0], load_after[0])
    console.print(
        f"Load average (1 min) before / after: {load_before[0]:.2f} / {load_after[0]:.2f} "
        f"on {os.cpu_count()} cores; times are the best of {plan.repeats} interleaved repeat(s)."
    )
    return {**setup, "rows": rows, "reference": reference, "time_to_error": tte}


def _speed_and_agreement(console: Console, ours: _Ours, theirs: _Mitsuba, plan: _Plan):
    table = Table(title="Speed and DC agreement at equal spp (ours / Mitsuba, warm, s per frame)")
    for col in ("bounces", "max_depth", "spp", "ours s", "Mitsuba s", "Mitsuba 1st s",
                "ours/Mitsuba", "scale", "rel RMSE", "max rel", f"rel RMSE {BLOCK_PX}x{BLOCK_PX}"):
        table.add_column(col, justify="right")
    rows = []
    for b in plan.bounces:
        ours.render(1, b, seed=0)  # compiles (or loads) the numba kernels of this path
        for spp in plan.spps:
            _, first = theirs.render(spp, b, seed=0)  # kernel compilation, not counted
            t_ours, t_mi = [], []
            for r in range(plan.repeats):
                img_o, _, dt = ours.render(spp, b, seed=1000 + r)
                t_ours.append(dt)
                img_m, dt = theirs.render(spp, b, seed=1000 + r)
                t_mi.append(dt)
            agr = agreement(img_o, img_m)
            row = {
                "bounces": b,
                "mitsuba_max_depth": b + 1,
                "spp": spp,
                "ours_s": min(t_ours),
                "mitsuba_s": min(t_mi),
                "mitsuba_first_s": first,
                "ratio_ours_over_mitsuba": min(t_ours) / min(t_mi),
                **agr,
            }
            rows.append(row)
            table.add_row(
                str(b), str(b + 1), str(spp), _fmt(row["ours_s"]), _fmt(row["mitsuba_s"]),
                _fmt(first), _fmt(row["ratio_ours_over_mitsuba"], ".2f"),
                _fmt(agr["scale"], ".4f"), _fmt(100 * agr["rel_rmse"], ".2f") + " %",
                _fmt(100 * agr["max_rel_err"], ".1f") + " %",
                _fmt(100 * agr["rel_rmse_blocks"], ".2f") + " %",
            )
    console.print(table)
    console.print(
        "scale: least-squares s in ours = s * Mitsuba (1 when radiance units and light match); "
        "rel RMSE = ||ours - s*Mitsuba|| / ||ours||, noise of both renderers included; max rel "
        f"over pixels brighter than {MAX_REL_FLOOR:g} of the maximum; the {BLOCK_PX}x{BLOCK_PX} "
        "block figure averages noise away; the scale is fitted on those block means (on noisy "
        "pixels it would be biased low). 'Mitsuba 1st' is its first render of the setting, "
        "which compiles the kernels of a new integrator (Dr.Jit may load them from its disk "
        "cache); it is excluded from the ratio."
    )
    return rows


def _reference_check(console: Console, ours: _Ours, theirs: _Mitsuba, plan: _Plan) -> dict:
    n, b = plan.reference_spp, plan.reference_bounces
    ours.render(1, b, seed=0)
    ref, ref_var, t_ref = ours.render(n, b, seed=7)
    # Mitsuba in 8 independent chunks: their spread gives its per-pixel noise
    chunks = 8 if n >= 8 else 1
    per = max(1, n // chunks)
    theirs.render(per, b, seed=0)
    imgs, t_mi = [], 0.0
    for k in range(chunks):
        img, dt = theirs.render(per, b, seed=10_000 + k)
        imgs.append(img)
        t_mi += dt
    stack = np.stack(imgs)
    mref = stack.mean(axis=0)
    mvar = stack.var(axis=0, ddof=1) / chunks if chunks > 1 else np.zeros_like(mref)
    agr = agreement(ref, mref)
    s = agr["scale"]
    norm = float(np.linalg.norm(ref))
    ref_noise = float(np.sqrt(ref_var.sum()) / norm)
    mi_noise = float(s * np.sqrt(mvar.sum()) / norm)
    expected = math.hypot(ref_noise, mi_noise)
    out = {
        "spp": n,
        "bounces": b,
        "mitsuba_spp": per * chunks,
        "ours_s": t_ref,
        "mitsuba_s": t_mi,
        **agr,
        "ours_noise_rel": ref_noise,
        "mitsuba_noise_rel": mi_noise,
        "rel_rmse_over_noise": agr["rel_rmse"] / expected if expected > 0 else float("nan"),
        "_image": ref,
        "_var": ref_var,
    }
    table = Table(title=f"High-spp reference check ({n} spp, {b} bounce(s))")
    for col in ("ours s", "Mitsuba s", "scale", "rel RMSE", f"rel RMSE {BLOCK_PX}x{BLOCK_PX}",
                "max rel", "noise ours", "noise Mitsuba", "RMSE / noise"):
        table.add_column(col, justify="right")
    table.add_row(
        _fmt(t_ref, ".2f"), _fmt(t_mi, ".2f"), _fmt(s, ".5f"),
        _fmt(100 * agr["rel_rmse"], ".3f") + " %", _fmt(100 * agr["rel_rmse_blocks"], ".3f") + " %",
        _fmt(100 * agr["max_rel_err"], ".1f") + " %", _fmt(100 * ref_noise, ".3f") + " %",
        _fmt(100 * mi_noise, ".3f") + " %", _fmt(out["rel_rmse_over_noise"], ".2f"),
    )
    console.print(table)
    verdict = (
        "agree within Monte Carlo noise" if out["rel_rmse_over_noise"] < 1.3
        else "differ by more than their Monte Carlo noise"
    )
    console.print(
        f"The references {verdict} (RMSE / noise = {out['rel_rmse_over_noise']:.2f}; ~1 means "
        f"the difference is noise alone). Scale {s:.5f}: "
        + ("units match." if abs(s - 1.0) < 0.01 else
           "NOT 1: a radiance unit, light intensity or albedo convention differs between the "
           "two; the errors above are after removing it.")
    )
    return out


def _time_to_error(
    console: Console, ours: _Ours, theirs: _Mitsuba, plan: _Plan, reference: dict
) -> dict:
    ref, ref_var = reference["_image"], reference["_var"]
    scale = reference["scale"]
    b = plan.reference_bounces
    norm = float(np.linalg.norm(ref))
    ref_noise = float(np.sqrt(ref_var.sum()) / norm)
    target = plan.target_rel_rmse

    def corrected(err: float) -> float:
        # the reference's own noise adds in quadrature to every error measured against it
        return math.sqrt(max(err * err - ref_noise * ref_noise, 0.0))

    sweep = {"ours": {"spp": [], "seconds": [], "rel_rmse_raw": [], "rel_rmse": []},
             "mitsuba": {"spp": [], "seconds": [], "rel_rmse_raw": [], "rel_rmse": []}}
    for spp in plan.sweep_spps:
        theirs.render(spp, b, seed=0)
        t = {"ours": [], "mitsuba": []}
        e = {"ours": [], "mitsuba": []}
        for r in range(plan.repeats):
            img, _, dt = ours.render(spp, b, seed=2000 + r)
            t["ours"].append(dt)
            e["ours"].append(rel_rmse(img, ref))
            img, dt = theirs.render(spp, b, seed=2000 + r)
            t["mitsuba"].append(dt)
            e["mitsuba"].append(rel_rmse(scale * img, ref))
        for who in ("ours", "mitsuba"):
            raw = float(np.sqrt(np.mean(np.square(e[who]))))
            sweep[who]["spp"].append(spp)
            sweep[who]["seconds"].append(min(t[who]))
            sweep[who]["rel_rmse_raw"].append(raw)
            sweep[who]["rel_rmse"].append(corrected(raw))
    result: dict = {"target_rel_rmse": target, "bounces": b, "reference_noise_rel": ref_noise}
    for who, sw in sweep.items():
        secs, ext_t = loglog_crossing(sw["seconds"], sw["rel_rmse"], target)
        spp_at, ext_s = loglog_crossing(sw["spp"], sw["rel_rmse"], target)
        result[who] = {**sw, "seconds_to_target": secs, "spp_to_target": spp_at,
                       "extrapolated": ext_t or ext_s}
    o, m = result["ours"]["seconds_to_target"], result["mitsuba"]["seconds_to_target"]
    result["ratio_ours_over_mitsuba"] = o / m if m and np.isfinite(m) and m > 0 else float("nan")

    table = Table(title=f"DC error against our {reference['spp']}-spp reference, {b} bounce(s)")
    for col in ("spp", "ours s", "ours rel RMSE", "Mitsuba s", "Mitsuba rel RMSE"):
        table.add_column(col, justify="right")
    for i, spp in enumerate(plan.sweep_spps):
        table.add_row(
            str(spp), _fmt(sweep["ours"]["seconds"][i]),
            _fmt(100 * sweep["ours"]["rel_rmse"][i], ".2f") + " %",
            _fmt(sweep["mitsuba"]["seconds"][i]),
            _fmt(100 * sweep["mitsuba"]["rel_rmse"][i], ".2f") + " %",
        )
    for who, label in (("ours", "ours"), ("mitsuba", "Mitsuba")):
        r = result[who]
        table.add_row(
            f"{label} @ {100 * target:g} %",
            _fmt(r["seconds_to_target"]) if who == "ours" else "",
            f"{_fmt(r['spp_to_target'], '.0f')} spp" if who == "ours" else "",
            _fmt(r["seconds_to_target"]) if who == "mitsuba" else "",
            f"{_fmt(r['spp_to_target'], '.0f')} spp" if who == "mitsuba" else "",
        )
    console.print(table)
    ext = [w for w in ("ours", "mitsuba") if result[w]["extrapolated"]]
    console.print(
        f"Time to {100 * target:g} % relative RMSE: ours {_fmt(o)} s, Mitsuba {_fmt(m)} s, "
        f"ratio ours/Mitsuba {_fmt(result['ratio_ours_over_mitsuba'], '.2f')}"
        + (f" (extrapolated for {', '.join(ext)})" if ext else "")
        + f". Errors are ||img - ref|| / ||ref|| with the reference's own noise "
        f"({100 * ref_noise:.2f} %) removed in quadrature; Mitsuba's images are scaled by the "
        f"reference-fitted {scale:.5f}; interpolated in log-log between sweep points."
    )
    return result
