"""The rig calibration's verdicts: every key ``calibration.yaml`` gets, from the fit's evidence.

Each key of the file (:func:`calibration_keys`) is judged by :func:`calibration.verdicts.judge`
against its limit, the target the earlier issues set for it (:data:`TARGETS`, the round trips'
assertions, docs/calibration.md), from the evidence of the procedure that estimated it:

- **camera and turntable** (the joint bundle adjustment): the corners' reprojection residual
  against the corner detector's noise (:func:`calibration.board_detection.saddle_std_px` of
  each corner, from the noise model of the noise stacks), as a reduced chi-square per view and
  for the stage (OpenCV's free-pose start and the joint adjustment); the parameters' standard
  deviations from the adjustment's Jacobian at that noise, made honest by the chi-square, and
  never below their spread over the fixtures (delete-one-fixture jackknife: a fixture's views
  share one board pose, so their errors are not independent). ``k3`` is held at 0 (not
  determined at this resolution); the axis point along the axis is a convention (the point
  nearest the nominal one), not an estimate.
- **depth**: the residual after the depth model against each pixel's phase noise (reduced
  chi-square per view and overall); offset and wiggling are determined together, over the
  phases the sweep saw only; a pixel offset's standard deviation from its samples.
- **sensor**: the photon transfer line's reduced chi-square over its bins and the fit's
  standard errors.
- **source power**: the white squares' ratios against one another (reduced chi-square of the
  squares' medians); the standard error the larger of the pixels' and the squares' spread.
- **solar simulator**: the normalised residuals of the intensity response; a reference-cell
  reading is the operator's number, not determined by the frames.

A view whose reprojection chi-square is above :data:`~calibration.verdicts.CHI2_UNEXPLAINED`
while most views are explained is an outlier the sequence drops (``results["views"]
["unexplained"]`` lists it with its chi-square) and the adjustment runs without it; when more
than :data:`MAX_DROPPED_SHARE` of the views would go, the model, not the views, is wrong and the
keys the stage drives are ``unexplained``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.verdicts import (
    CHI2_UNEXPLAINED,
    Verdict,
    Verdicts,
    above_limit,
    chi2_limit_for,
    honest_std,
    jackknife_covariance_of,
    judge,
)
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.twin_file import CalibrationFile

#: the keys the file holds as one value though it is a mapping (a grid of offsets)
LEAF_MAPPINGS = frozenset({"camera.depth.pixel_offset_m"})

#: the earlier issues' targets (issue 13: docs/calibration.md, tests/calibration/
#: test_rig_roundtrip.py): relative ones as a share of the value
FOCAL_REL = 0.005
PRINCIPAL_POINT_PX = 0.5
#: the reprojection target [px]: a distortion coefficient is determined when its standard
#: deviation moves the image's corner by less than this
REPROJECTION_PX = 0.3
AXIS_DIRECTION_DEG = 0.2
AXIS_POINT_M = 0.002
ZERO_OFFSET_DEG = 0.1
DEPTH_MODEL_M = 0.002
GAIN_REL = 0.05
READ_NOISE_REL = 0.10
POWER_REL = 0.03
SOLAR_REL = 0.03
#: the share of the views that may be dropped as unexplained before the model is blamed
MAX_DROPPED_SHARE = 0.25


def calibration_keys(calibration: CalibrationFile) -> list[str]:
    """The keys the calibration file holds (as written: defaults left out), dotted
    (``camera.distortion.k1``, ``camera.depth.pixel_offset_m``); the provenance is not a key."""
    data = calibration.model_dump(mode="json", exclude_defaults=True)
    data.pop("provenance", None)
    keys: list[str] = []

    def walk(prefix: str, value: Any) -> None:
        if isinstance(value, Mapping) and prefix not in LEAF_MAPPINGS:
            for k, v in value.items():
                walk(f"{prefix}.{k}" if prefix else str(k), v)
        else:
            keys.append(prefix)

    walk("", data)
    return keys


def reduced_chi2(residuals: np.ndarray, std: np.ndarray, n_params: int = 0) -> float:
    """``sum((r / s)^2) / (n - n_params)`` over the finite, positive ``std``; inf when no
    degree of freedom is left (nothing to judge a fit by is no evidence that it fits)."""
    r = np.asarray(residuals, dtype=np.float64).ravel()
    s = np.asarray(std, dtype=np.float64).ravel()
    ok = np.isfinite(r) & np.isfinite(s) & (s > 0)
    dof = int(ok.sum()) - n_params
    if dof <= 0:
        return math.inf
    with np.errstate(over="ignore"):  # a residual beyond a float's range: chi-square inf
        return float(np.sum((r[ok] / s[ok]) ** 2) / dof)


def jackknife_std(estimates: Sequence[np.ndarray | float]) -> np.ndarray:
    """Delete-one-group jackknife standard deviation of an estimate from its ``g`` leave-one-
    out values: ``sqrt((g - 1) / g * sum((x_i - mean)^2))`` per component; inf with fewer than
    two groups (one group has no spread to measure)."""
    x = np.asarray([np.atleast_1d(np.asarray(e, dtype=np.float64)) for e in estimates])
    if x.shape[0] < 2:
        return np.full(x.shape[1:] if x.ndim > 1 else (1,), np.inf)
    return np.sqrt(np.diag(jackknife_covariance_of(x.reshape(x.shape[0], -1))))


def unexplained_views(per_view_chi2: Mapping[str, float],
                      chi2_limit: float = CHI2_UNEXPLAINED) -> tuple[list[str], bool]:
    """The views whose reduced chi-square is above ``chi2_limit`` (:func:`calibration.verdicts.
    above_limit`: worst first, not finite counts as above), and whether they may be dropped:
    True when they are at most :data:`MAX_DROPPED_SHARE` of the views (outliers), False when
    more (the model is wrong)."""
    bad = above_limit(per_view_chi2, chi2_limit)
    return bad, len(bad) <= MAX_DROPPED_SHARE * len(per_view_chi2)


@dataclass(frozen=True)
class StageEvidence:
    """One fitting stage's goodness of fit: its reduced chi-square, what it names in a reason,
    the views (or parts) it could not explain, and its degrees of freedom when they are few
    (the chi-square's own noise then raises the limit: :func:`calibration.verdicts.
    chi2_limit_for`)."""

    reduced_chi2: float
    where: str
    unexplained: tuple[str, ...] = ()
    dof: int | None = None

    @property
    def chi2_limit(self) -> float:
        return CHI2_UNEXPLAINED if self.dof is None else chi2_limit_for(self.dof)

    def judged(self, std: float | Sequence[float], limit: float, unit: str = "",
               note: str | None = None, already_honest: bool = False) -> Verdict:
        """:func:`calibration.verdicts.judge` at this stage's chi-square (``std`` the
        statistical one, or ``already_honest``: scaled by the chi-square or a spread already,
        so not scaled again); views it could not explain make it ``unexplained``; a determined
        verdict carries ``note`` (a condition, such as the span it holds over)."""
        chi2 = self.reduced_chi2
        explained = math.isfinite(chi2) and chi2 <= self.chi2_limit
        v = judge(std, limit, reduced_chi2=1.0 if already_honest and explained else chi2,
                  chi2_limit=self.chi2_limit, unit=unit, where=self.where)
        if not explained and already_honest:
            return Verdict("unexplained", _as_std(std), v.reason)
        if explained and self.unexplained:
            shown = ", ".join(self.unexplained[:6])
            more = f" and {len(self.unexplained) - 6} more" if len(self.unexplained) > 6 else ""
            return Verdict("unexplained", v.std,
                           f"{self.where}: {len(self.unexplained)} views the model does not "
                           f"explain (reduced chi-square above {CHI2_UNEXPLAINED:g}): "
                           f"{shown}{more}")
        if v.determined and note:
            return Verdict("determined", v.std, note)
        return v


def _as_std(std: float | Sequence[float]) -> float | list[float]:
    return float(std) if isinstance(std, int | float) else [float(s) for s in std]


@dataclass(frozen=True)
class CameraTurntableEvidence:
    """What the joint adjustment of camera and turntable says of its parameters.

    ``std`` are its Jacobian's standard deviations at the corners' noise (before the chi-square
    scaling, which :meth:`StageEvidence.judged` applies), ``spread`` the jackknife's over the
    fixtures (already a spread: never scaled), both by parameter name
    (:data:`calibration.turntable_axis.CAMERA_PARAMETERS`, ``axis_u`` ...); ``basis`` the unit
    vectors of ``axis_u``/``point_u`` and ``axis_v``/``point_v``.
    """

    stage: StageEvidence
    std: Mapping[str, float]
    spread: Mapping[str, float] = field(default_factory=dict)
    basis: np.ndarray | None = None
    fx_px: float = 0.0
    fy_px: float = 0.0
    #: the largest normalised image radius of the corners seen (x / f, y / f)
    corner_radius: float = 0.6

    def combined(self, name: str) -> float:
        """The parameter's standard deviation: the Jacobian's made honest, never below its
        spread over the fixtures."""
        s = honest_std(self.std.get(name, math.inf), self.stage.reduced_chi2)
        return max(s, self.spread.get(name, 0.0))


def distortion_limit(coefficient: str, fx_px: float, radius: float) -> float:
    """The standard deviation of a distortion coefficient that moves a point at normalised
    radius ``radius`` by :data:`REPROJECTION_PX` (OpenCV's model: k1 r^3, k2 r^5, k3 r^7, the
    tangential terms up to 3 p r^2) [the coefficient's unit, 1]."""
    r = max(radius, 1e-3)  # a radius of 0 sees no distortion: the limit is then very wide
    reach = {"k1": r**3, "k2": r**5, "k3": r**7, "p1": 3 * r**2, "p2": 3 * r**2}[coefficient]
    return REPROJECTION_PX / (max(fx_px, 1e-9) * reach)


def camera_turntable_verdicts(ev: CameraTurntableEvidence, distortion_keys: Sequence[str]
                              ) -> dict[str, Verdict]:
    """The verdicts of ``camera.fx_px`` ... ``camera.distortion.*`` and ``turntable.*``."""
    out: dict[str, Verdict] = {}
    for name, limit in (("fx_px", FOCAL_REL * ev.fx_px), ("fy_px", FOCAL_REL * ev.fy_px),
                        ("cx_px", PRINCIPAL_POINT_PX), ("cy_px", PRINCIPAL_POINT_PX)):
        out[f"camera.{name}"] = _judged_spread(ev, [name], limit, " px")
    for coef in distortion_keys:
        if coef == "k3":
            out["camera.distortion.k3"] = Verdict(
                "not determined", None, "held at 0: at 224 x 171 pixels the sixth-order term "
                "trades off against k1 and k2 (calibration/intrinsics.py)")
            continue
        out[f"camera.distortion.{coef}"] = _judged_spread(
            ev, [coef], distortion_limit(coef, ev.fx_px, ev.corner_radius))
    # The axis' tilt and the point's shift along the two unit vectors normal to the nominal
    # axis: components in the world frame (the basis' rows), each the larger of its two parts.
    basis = np.eye(3)[:2] if ev.basis is None else np.asarray(ev.basis, dtype=np.float64)
    for key, names, limit, unit, note in (
            ("turntable.axis_direction", ("axis_u", "axis_v"),
             math.sin(math.radians(AXIS_DIRECTION_DEG)), "", None),
            ("turntable.axis_point_m", ("point_u", "point_v"), AXIS_POINT_M, " m",
             "normal to the axis only: the point along it is the one nearest the nominal "
             "axis point, a convention")):
        s = np.array([ev.combined(n) for n in names])
        world = np.sqrt((basis.T**2) @ s**2) if np.all(np.isfinite(s)) else np.full(3, np.inf)
        out[key] = ev.stage.judged([float(x) for x in world], limit, unit, note,
                                   already_honest=True)
    out["turntable.zero_offset_deg"] = _judged_spread(ev, ["zero_offset_deg"],
                                                      ZERO_OFFSET_DEG, " deg")
    return out


def _judged_spread(ev: CameraTurntableEvidence, names: Sequence[str], limit: float,
                   unit: str = "") -> Verdict:
    s = [ev.combined(n) for n in names]
    return ev.stage.judged(s[0] if len(s) == 1 else s, limit, unit, already_honest=True)


@dataclass(frozen=True)
class DepthEvidence:
    """The depth fit's evidence (:class:`calibration.depth.DepthCalibration`)."""

    stage: StageEvidence
    model_std_rad: Sequence[float]
    pixel_offset_std_m: float
    frequencies_hz: Sequence[float]
    phase_span_rad: tuple[float, float]
    range_span_m: tuple[float, float]
    coverage: float


def depth_verdicts(ev: DepthEvidence, keys: Sequence[str]) -> dict[str, Verdict]:
    """``camera.depth.phase_offset_rad``, ``.wiggling`` (determined together: over a narrow
    span of phases the offset and the low harmonics are nearly one direction) and
    ``.pixel_offset_m``, each against the depth model's target (2 mm of range)."""
    f = np.asarray(ev.frequencies_hz, dtype=np.float64)
    limit_rad = [4 * math.pi * fk * DEPTH_MODEL_M / SPEED_OF_LIGHT_M_S for fk in f]
    span = (f"over the phases seen only ({ev.phase_span_rad[0]:.2f}-{ev.phase_span_rad[1]:.2f} "
            f"rad, ranges {ev.range_span_m[0]:.2f}-{ev.range_span_m[1]:.2f} m)")
    out: dict[str, Verdict] = {}
    model = [float(s) for s in ev.model_std_rad] or [math.inf]
    # the tightest frequency's limit: the largest phase per metre
    lim = min(limit_rad) if limit_rad else 0.0
    for key in keys:
        if key == "camera.depth.phase_offset_rad":
            out[key] = ev.stage.judged(model if len(model) > 1 else model[0], lim, " rad",
                                       f"with camera.depth.wiggling, {span}")
        elif key == "camera.depth.wiggling":
            out[key] = ev.stage.judged(max(model), lim, " rad",
                                       f"with camera.depth.phase_offset_rad, {span}")
        elif key == "camera.depth.pixel_offset_m":
            note = None if ev.coverage >= 0.999 else (
                f"on the {100 * ev.coverage:.0f} % of the pixels the board covered; elsewhere 0")
            out[key] = ev.stage.judged(ev.pixel_offset_std_m, DEPTH_MODEL_M, " m", note)
    return out


def relative_verdict(value: float, std: float, rel_limit: float, stage: StageEvidence,
                     unit: str = "") -> Verdict:
    """A key whose target is relative (gain, read noise, power, scale): its limit is
    ``rel_limit`` of its value."""
    limit = rel_limit * abs(value) if math.isfinite(value) else 0.0
    return stage.judged(std, limit, unit)


def rig_verdicts(keys: Sequence[str], camera: CameraTurntableEvidence, depth: DepthEvidence,
                 others: Mapping[str, Verdict]) -> Verdicts:
    """Every key of ``keys`` judged: camera and turntable, depth, then ``others`` (sensor,
    power, solar); a key none of them judges is a bug of the sequence (an error, not a silent
    gap in verdicts.json)."""
    distortion = [k.rsplit(".", 1)[1] for k in keys if k.startswith("camera.distortion.")]
    judged: dict[str, Verdict] = {
        **camera_turntable_verdicts(camera, distortion),
        **depth_verdicts(depth, [k for k in keys if k.startswith("camera.depth.")]),
        **others,
    }
    missing = [k for k in keys if k not in judged]
    if missing:
        raise ValueError(f"no verdict for {', '.join(missing)}: the sequence writes keys it "
                         "does not judge")
    return Verdicts({k: judged[k] for k in keys})


__all__ = ["CameraTurntableEvidence", "DepthEvidence", "StageEvidence", "calibration_keys",
           "camera_turntable_verdicts", "depth_verdicts", "distortion_limit", "jackknife_std",
           "reduced_chi2", "relative_verdict", "rig_verdicts", "unexplained_views"]
