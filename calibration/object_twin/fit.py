"""The object twin from measured frames: mount pose and reflectance (issue 14, section 3).

:func:`fit_object` takes averaged captures of the mounted object at some turntable angles (what
``toftwin fit-object`` or a campaign's first poses capture; it never drives the rig) and:

1. turns every view into points (:mod:`calibration.object_twin.point_cloud`: calibrated
   intrinsics, depth errors removed, edges dropped) and checks each has enough;
2. registers the merged points to the mounted objects' meshes by point-to-plane ICP from the
   nominal pose (:mod:`calibration.object_twin.pose`), or refuses when they do not overlap;
3. renders the views at that pose (:mod:`calibration.object_twin.render_model`: the effect plan
   and the static surroundings once per view, then only the pixels around the mounted objects
   for every candidate), decides which objects' scales the views determine (objects with too
   few pixels or too little signal are reported as undetermined) and starts their scales at the
   linear least-squares ratio of measured to rendered phasors
   (:mod:`calibration.object_twin.reflectance`);
4. fits pose and scales together by maximum likelihood on the measured raw phasors
   (:mod:`calibration.object_twin.refine`: weighted by the sensor's noise and the renders' Monte
   Carlo variance), with the uncertainties. ICP is the start and the overlap check; the
   rendered phasors settle what ICP's biased ranges cannot (the height along the axis, which
   only the silhouette shows, and the range biases of mixed pixels, blur and glints).

The result is the object file (:class:`sim_core.twin_file.ObjectTwinFile`) with the report in
its provenance. BRDF roughness is not fitted: the glossy films' specular lobes (a degree wide)
appear in at most a pixel patch of one view, which does not determine it; the report says so.
"""

from __future__ import annotations

import datetime as dt
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from calibration.captures import AveragedCapture
from calibration.object_twin.judgement import (
    POSITION_KEY,
    ROTATION_KEY,
    after_dropped_views,
    estimates,
    object_verdicts,
    scale_key,
    unfit_views,
)
from calibration.object_twin.point_cloud import (
    EDGE_JUMP_M,
    MIN_AMPLITUDE_DN,
    capture_cloud,
    usable_pixels,
)
from calibration.object_twin.pose import mount_model, register_mount
from calibration.object_twin.refine import refine_object_twin
from calibration.object_twin.reflectance import object_pixels, scale_ratio
from calibration.object_twin.render_model import FIT_RENDER, TwinRenderer, measured_phasor
from calibration.object_twin.views import calibrated_camera, capture_spec, mount_from_camera
from calibration.verdicts import CHI2_UNEXPLAINED, Verdicts
from sim_core.depth_errors import DepthErrorModel
from sim_core.errors import InvalidInputError
from sim_core.geometry import triangle_areas
from sim_core.json_safe import json_safe
from sim_core.render import RenderSettings
from sim_core.scene_spec import SceneSpec
from sim_core.twin_file import (
    MountParameters,
    ObjectParameters,
    ObjectTwinFile,
    ObjectTwinParameters,
    Provenance,
    TwinParameters,
    has_object_keys,
)

#: least usable pixels (signal, not flagged) a view must have
MIN_VALID_PIXELS = 300


@dataclass(frozen=True)
class ObjectFit:
    """The fitted object twin, its report (plain JSON) and each key's verdict."""

    object_twin: ObjectTwinFile
    report: dict[str, Any]
    verdicts: Verdicts = field(default_factory=Verdicts)


def _too_few_pixels(cap: AveragedCapture, n_usable: int, min_valid_pixels: int,
                    min_amplitude_dn: float) -> str:
    return (f"{n_usable} valid pixels (amplitude >= {min_amplitude_dn:g} DN, not saturated) at "
            f"{cap.turntable_angle_deg:g} deg; at least {min_valid_pixels} are needed (is the "
            "lamp on, the object in view?)")


def _check_captures(captures: Sequence[AveragedCapture], min_valid_pixels: int,
                    min_amplitude_dn: float) -> list[np.ndarray]:
    if not captures:
        raise InvalidInputError("captures", "no captures: at least one view of the mounted "
                                "object is needed (better three or more turntable angles)")
    usable = []
    for i, cap in enumerate(captures):
        if not np.isfinite(cap.turntable_angle_deg):
            raise InvalidInputError(f"captures[{i}].turntable_angle_deg",
                                    "the capture does not say the turntable's angle")
        u = usable_pixels(cap.amplitude, cap.valid, min_amplitude_dn)
        if int(u.sum()) < min_valid_pixels:
            raise InvalidInputError(f"captures[{i}]", _too_few_pixels(
                cap, int(u.sum()), min_valid_pixels, min_amplitude_dn))
        usable.append(u)
    return usable


def _dark_views(captures: Sequence[AveragedCapture], min_valid_pixels: int,
                min_amplitude_dn: float) -> list[dict[str, Any]]:
    """The views with too few usable pixels to fit, each with its reason (the report's
    ``dropped_views`` form)."""
    out = []
    for i, cap in enumerate(captures):
        n = int(usable_pixels(cap.amplitude, cap.valid, min_amplitude_dn).sum())
        if n < min_valid_pixels:
            out.append({"index": i, "turntable_angle_deg": cap.turntable_angle_deg,
                        "reduced_chi2": None, "reason": _too_few_pixels(
                            cap, n, min_valid_pixels, min_amplitude_dn) + ": left out"})
    return out


def _with_dropped(fit: ObjectFit, dropped: list[dict[str, Any]], t0: float) -> ObjectFit:
    """``fit`` with ``dropped`` added to its report's ``dropped_views`` (and provenance)."""
    report = {**fit.report, "dropped_views": [*dropped, *fit.report["dropped_views"]]}
    report["seconds"] = {**report["seconds"], "total": time.perf_counter() - t0}
    twin = fit.object_twin
    twin = twin.model_copy(update={"provenance": twin.provenance.model_copy(update={
        "procedures": {**twin.provenance.procedures, "object_fit": report}})})
    return ObjectFit(twin, report, fit.verdicts)


def measured_points(
    spec: SceneSpec,
    calibration: TwinParameters | None,
    captures: Sequence[AveragedCapture],
    min_amplitude_dn: float = MIN_AMPLITUDE_DN,
    edge_jump_m: float = EDGE_JUMP_M,
) -> tuple[np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """Every view's points in the mount frame, merged: what ICP registers (step 1-2).

    Returns
    -------
    points : (n, 3) float64
        The merged points [m], mount frame.
    cameras : (n_views, 3) float64
        Each view's camera position in the mount frame [m].
    views : list of dict
        Per view: angle, frames, usable pixels and points (the report's ``views``).
    """
    points, cams, views = [], [], []
    for cap in captures:
        cspec = capture_spec(spec, cap)
        intr = calibrated_camera(cspec, calibration).intrinsics
        depth = calibration.camera.depth if calibration is not None else None
        model_d = None if depth is None else DepthErrorModel.from_spec(
            depth, cap.frequencies_hz, cap.shape)
        temperature = calibration.camera.temperature if calibration is not None else None
        cloud = capture_cloud(cap, intr, model_d, min_amplitude_dn, edge_jump_m, temperature)
        m = mount_from_camera(cspec, calibration, cap.turntable_angle_deg)
        points.append(cloud.points_cam_m @ m[:3, :3].T + m[:3, 3])
        cams.append(m[:3, 3])
        views.append({"turntable_angle_deg": cap.turntable_angle_deg, "frames": cap.n_frames,
                      "usable_pixels": int(cloud.usable.sum()), "points": cloud.n_points})
    return np.concatenate(points), np.asarray(cams), views


def fit_object(
    spec: SceneSpec,
    base_dir: str | Path,
    calibration: TwinParameters | None,
    captures: Sequence[AveragedCapture],
    *,
    render_settings: RenderSettings = FIT_RENDER,
    min_valid_pixels: int = MIN_VALID_PIXELS,
    min_amplitude_dn: float = MIN_AMPLITUDE_DN,
    edge_jump_m: float = EDGE_JUMP_M,
    rig_name: str = "",
    drop_unfit_views: bool = True,
) -> ObjectFit:
    """Fit the mount's pose offset and the objects' reflectance scales (module docstring).

    Parameters
    ----------
    spec, base_dir
        The nominal scene (its on-turntable objects are the mount) and its folder.
    calibration : TwinParameters or None
        The rig's calibration (None: nominal camera and rig). Its object keys, if it has any,
        are not used: the object twin is what is being fitted.
    captures : sequence of AveragedCapture
        Averaged frames of the mounted object, each at one reported turntable angle, the solar
        simulator's shutter closed.
    render_settings : RenderSettings
        How the twin renders the views for the reflectance and the refinement.
    min_valid_pixels, min_amplitude_dn, edge_jump_m
        The view checks and the point cloud's filters.
    rig_name : str
        Recorded in the provenance.
    drop_unfit_views : bool
        When the fit does not explain some views (their reduced chi-square above
        :data:`calibration.verdicts.CHI2_UNEXPLAINED`) and other views explain theirs, fit again
        without the others (at least two views kept); the report's ``dropped_views`` names
        them with their chi-square. With fewer than two views explained every key is
        ``unexplained``.

    Raises
    ------
    InvalidInputError
        ``captures[i]`` with too few valid pixels when fewer than two views have enough (with
        more, those views are left out and named in ``dropped_views``); ``mesh`` when the
        measured points do not overlap the mounted objects' meshes (never a pose in that case).
    """
    t0 = time.perf_counter()
    base = Path(base_dir)
    if calibration is not None and has_object_keys(calibration):
        calibration = TwinParameters(**{k: getattr(calibration, k)
                                         for k in TwinParameters.model_fields})
    captures = list(captures)
    dark = _dark_views(captures, min_valid_pixels, min_amplitude_dn)
    if dark and len(captures) - len(dark) >= 2:
        # Views too dark to fit carry no evidence for or against the model: the others are
        # fitted and the report names them.
        lit = {d["index"] for d in dark}
        again = fit_object(spec, base, calibration,
                           [c for i, c in enumerate(captures) if i not in lit],
                           render_settings=render_settings, min_valid_pixels=min_valid_pixels,
                           min_amplitude_dn=min_amplitude_dn, edge_jump_m=edge_jump_m,
                           rig_name=rig_name, drop_unfit_views=drop_unfit_views)
        return _with_dropped(again, [{k: v for k, v in d.items() if k != "index"}
                                     for d in dark], t0)
    usable = _check_captures(captures, min_valid_pixels, min_amplitude_dn)
    model = mount_model(spec, base)

    # 1-2. points, ICP ------------------------------------------------------------------------
    points, cams, views = measured_points(spec, calibration, captures, min_amplitude_dn,
                                          edge_jump_m)
    reg = register_mount(points, model, cams)
    t_icp = time.perf_counter() - t0

    # 3. the twin's prediction at the ICP pose; which objects it determines; starting scales -
    t1 = time.perf_counter()
    scales = {n: 1.0 for n in model.names}

    def twin_at(pose, s):
        return ObjectTwinParameters(
            mount=MountParameters(pose_offset=pose),
            objects={n: ObjectParameters(reflectance_scale=v) for n, v in s.items()})

    start = twin_at(reg.offset, scales)
    renderer = TwinRenderer(spec, base, calibration, captures, render_settings, start,
                            model.names)
    predicted = renderer.predict(start)
    measured = [measured_phasor(c) for c in captures]
    scene_names = tuple(o.name for o in spec.objects)
    pixels = object_pixels(model.names, scene_names, predicted, usable)
    fitted = tuple(n for n in model.names if pixels[n].determined)
    weights = [np.ones(c.shape) for c in captures]
    for n in fitted:
        scales[n] *= scale_ratio(measured, predicted, pixels[n].masks, weights)
    linear = dict(scales)
    t_setup = time.perf_counter() - t1

    # 4. pose and scales together: maximum likelihood on the phasors ------------------------
    areas = triangle_areas(model.triangles_m)
    centroid = (model.triangles_m.mean(axis=1) * areas[:, None]).sum(axis=0) / areas.sum()
    refined = refine_object_twin(renderer, captures, reg.offset, centroid, scales, fitted)
    angles = [c.turntable_angle_deg for c in captures]
    verdicts = object_verdicts(refined, pixels, angles)
    unfit = unfit_views(refined.chi2_per_view)
    # A view above the limit is not explained, however well the others (with more pixels,
    # or more of them) pull the fit's chi-square as a whole below it.
    if drop_unfit_views and unfit and len(captures) - len(unfit) >= 2:
        kept = [c for i, c in enumerate(captures) if i not in unfit]
        again = fit_object(spec, base, calibration, kept, render_settings=render_settings,
                           min_valid_pixels=min_valid_pixels, min_amplitude_dn=min_amplitude_dn,
                           edge_jump_m=edge_jump_m, rig_name=rig_name, drop_unfit_views=False)
        dropped = [{"turntable_angle_deg": angles[i],
                    "reduced_chi2": refined.chi2_per_view[i],
                    "reason": f"the model does not explain this view (reduced chi-square "
                              f"{refined.chi2_per_view[i]:.3g} after the fit with every view, "
                              f"above {CHI2_UNEXPLAINED:g}): left out"} for i in unfit]
        refit = again.report
        marked = after_dropped_views(
            again.verdicts,
            estimates(refined.offset.position_m, refined.offset.rotation_deg, refined.scales),
            estimates(again.object_twin.mount.pose_offset.position_m,
                      again.object_twin.mount.pose_offset.rotation_deg,
                      {n: e["reflectance_scale"] for n, e in refit["objects"].items()}),
            "views " + ", ".join(f"{angles[i]:+g} deg" for i in unfit))
        for n, entry in refit["objects"].items():
            verdict = marked[scale_key(n)]
            entry.update(determined=verdict.determined, verdict=verdict.verdict)
            if not verdict.determined:
                entry["reason"] = verdict.reason
        refit["pose_determined"] = marked[POSITION_KEY].determined and marked[
            ROTATION_KEY].determined
        refit["verdicts"] = marked.to_json()
        refit["dropped_views"] = dropped
        refit["with_every_view"] = json_safe(
            {"refined": refined.summary(), "verdicts": verdicts.to_json()}, non_finite=None)
        refit["seconds"]["total"] = time.perf_counter() - t0
        twin = again.object_twin
        twin = twin.model_copy(update={
            "objects": {n: p for n, p in twin.objects.items()
                        if marked[scale_key(n)].determined},
            "provenance": twin.provenance.model_copy(
                update={"procedures": {**twin.provenance.procedures, "object_fit": refit}})})
        return ObjectFit(twin, refit, marked)
    final_pred = refined.predicted
    objects_report = {}
    for n in model.names:
        px = pixels[n]
        verdict = verdicts[scale_key(n)]
        entry: dict[str, Any] = {"determined": verdict.determined, "verdict": verdict.verdict,
                                 "pixels": px.n_pixels,
                                 "mean_amplitude_dn": px.mean_amplitude_dn}
        if px.determined:
            k = scale_ratio(measured, final_pred, px.masks, weights)
            entry.update({
                "reflectance_scale": refined.scales[n],
                "std": verdict.std,
                "linear_estimate": linear[n],
                "amplitude_ratio_after": k,
            })
            if not verdict.determined:
                entry["reason"] = verdict.reason
        else:
            entry.update({"reflectance_scale": 1.0, "reason": px.reason})
        objects_report[n] = entry
    pose_determined = (verdicts[POSITION_KEY].determined
                       and verdicts[ROTATION_KEY].determined)
    report = json_safe({
        "views": views,
        "icp": reg.summary(),
        "refined": refined.summary(),
        "pose_determined": pose_determined,
        "verdicts": verdicts.to_json(),
        "dropped_views": [],
        "objects": objects_report,
        "roughness": {"determined": False, "reason": "the glossy films' specular lobes are about "
                      "a degree wide: they appear in at most a small patch of one view, which "
                      "does not determine the roughness; the presets' roughness is kept"},
        "render": {"integrator": render_settings.integrator, "spp": render_settings.spp,
                   "effects": "all",
                   "region_pixels": [int(r.sum()) for r in renderer.regions],
                   "renders": renderer.renders},
        "seconds": {"icp": t_icp, "setup": t_setup,
                    "refine": time.perf_counter() - t1 - t_setup,
                    "total": time.perf_counter() - t0},
    }, non_finite=None)
    determined_scales = {n: ObjectParameters(reflectance_scale=refined.scales[n])
                         for n in fitted if verdicts[scale_key(n)].determined}
    twin = ObjectTwinFile(
        mount=MountParameters(pose_offset=refined.offset),
        objects=determined_scales,
        provenance=Provenance(
            created_utc=dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
            rig=rig_name, software=f"toftwin {_version()}",
            frames_used=int(sum(c.n_frames for c in captures)),
            procedures={"object_fit": report}),
    )
    return ObjectFit(twin, report, verdicts)


def _version() -> str:
    try:
        return metadata.version("toftwin")
    except metadata.PackageNotFoundError:  # pragma: no cover - running from a checkout
        return "unknown"
