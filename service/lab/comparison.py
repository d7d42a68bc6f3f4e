"""Comparing a measured and a simulated frame: masks, loading frame folders, Table 5 and the
figures a ToF engineer reads first.

The metrics themselves are :func:`sim_core.metrics.compare_images`: the seed's Table 5 rows and
(``tof``) the depth difference over the pixels valid in both frames and flying in neither
(median, median absolute deviation, 95th percentile of its magnitude, in mm) and the share of
flying and invalid pixels of each frame. This module decides which pixels count
(:class:`~service.lab.requests.MaskSpec`); frame folders are read by :mod:`sim_core.frame_io`.
Where a second capture of the same state exists (campaigns with an object fit), the same
figures of the measured frame against it are the noise ceiling (:func:`explained_difference`);
where the fitted twin stays beyond it, :func:`unexplained_residual` says on which channel, by how
much and where (:mod:`sim_core.unexplained`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from service.lab.requests import MaskSpec
from sim_core import frame_io, metrics
from sim_core.edges import object_edge_mask
from sim_core.errors import InvalidInputError
from sim_core.frame_io import Frame
from sim_core.json_safe import json_safe
from sim_core.metrics import ComparisonReport
from sim_core.tof import ToFImage
from sim_core.unexplained import dark_next_to_bright, locate_excess

#: issue 14's ceiling: a fitted twin explains a pose when its depth RMSE is within this factor
#: of the noise ceiling's and its grey PSNR within :data:`CEILING_GREY_PSNR_DB` of it
CEILING_DEPTH_RMSE_RATIO = 1.25
CEILING_GREY_PSNR_DB = 1.0


def build_mask(
    mask: MaskSpec,
    measured: ToFImage,
    object_id: np.ndarray | None,
    object_names: list[str],
    turntable_ids: list[int],
) -> np.ndarray | None:
    """The boolean mask a :class:`MaskSpec` selects (None: every pixel).

    ``turntable`` (the default) selects the pixels the simulator saw hitting an object on the
    turntable, or any object when no object rides on it; ``objects`` the named objects;
    ``depth_window`` the measured range in [near_m, far_m]; ``region`` a rectangle of pixels.
    """
    shape = measured.range_m.shape
    if mask.kind == "all":
        return None
    if mask.kind == "depth_window":
        return metrics.mask_by_depth_window(measured.range_m, mask.near_m, mask.far_m)
    if mask.kind == "region":
        return metrics.mask_by_region(shape, tuple(mask.rows), tuple(mask.cols))
    if object_id is None:
        raise InvalidInputError(
            "mask.kind", f"{mask.kind!r} needs the simulator's object ids, which this frame lacks"
        )
    if mask.kind == "objects":
        ids = []
        for i, name in enumerate(mask.names):
            if name not in object_names:
                raise InvalidInputError(
                    f"mask.names[{i}]", f"unknown object {name!r}; allowed: {object_names}"
                )
            ids.append(object_names.index(name))
        return metrics.mask_from_objects(object_id, ids)
    if not turntable_ids:
        return np.asarray(object_id) >= 0
    return metrics.mask_from_objects(object_id, turntable_ids)


def compare(
    measured: ToFImage,
    simulated: ToFImage,
    mask: np.ndarray | None,
    grey_full_scales: tuple[float, float],
) -> ComparisonReport:
    """Seed Table 5 indexes of ``simulated`` against ``measured`` inside ``mask``.

    ``grey_full_scales``: each frame's own grey full scale (measured, simulated), as in its
    ``grey.png`` (:func:`sim_core.frame_io.grey_full_scale`), so the metrics' grey images are
    the frames' grey images.
    """
    return metrics.compare_images(measured, simulated, mask, grey_full_scale=grey_full_scales)


def _summary(report: ComparisonReport) -> dict[str, Any]:
    """The figures of one comparison the explained difference uses (plain floats), with its
    depth difference and pixel shares (``tof``, :class:`sim_core.metrics.ToFFigures`)."""
    return json_safe({
        "depth_rmse_m": math.sqrt(max(report.depth.mse, 0.0)) * report.depth_unit_m,
        "depth_mse": report.depth.mse,
        "depth_ssim": report.depth.ssim,
        "grey_psnr_db": report.grey.psnr_db,
        "grey_mse": report.grey.mse,
        "grey_ssim": report.grey.ssim,
        "n_pixels": report.n_pixels,
        "tof": None if report.tof is None else report.tof.to_dict(),
    })


def explained_fraction(nominal_mse: float, fitted_mse: float, ceiling_mse: float) -> float | None:
    """How much of the nominal twin's excess over the noise ceiling the fitted twin removes:
    ``1 - (fitted - ceiling) / (nominal - ceiling)`` (MSEs). 1: the fit explains the whole
    difference; 0: nothing; negative: the fit made it worse. None when the nominal twin is
    already at the ceiling (nothing to explain).

    >>> explained_fraction(10.0, 2.0, 1.0)
    0.888...
    >>> explained_fraction(1.0, 1.0, 1.0) is None
    True
    """
    excess = nominal_mse - ceiling_mse
    if not (math.isfinite(excess) and excess > 0.0 and math.isfinite(fitted_mse)):
        return None
    return 1.0 - (fitted_mse - ceiling_mse) / excess


def explained_difference(
    mask_spec: MaskSpec,
    measured: ToFImage,
    second: ToFImage,
    grey_full_scale: float,
    nominal: ComparisonReport | None,
    fitted_image: ToFImage,
    fitted_object_id: np.ndarray | None,
    fitted_grey_full_scale: float,
    object_names: list[str],
    turntable_ids: list[int],
) -> dict[str, Any]:
    """A pose's difference explained (issue 14, section 4): the measured frame against the
    nominal twin, against the fitted twin, and against a second capture of the same state (the
    noise ceiling: what no twin can beat).

    The fitted twin and the ceiling are compared inside the mask the fitted simulation gives
    (its objects sit where the measurement sees them); the nominal comparison keeps its own.
    Returns ``{"nominal": ..., "fitted": ..., "ceiling": ..., "explained": {"depth": f,
    "grey": f}}`` with the figures of :func:`_summary` (each with its ``tof`` figures: the
    ceiling's are the depth difference and pixel shares between two captures, what no twin can
    beat) and :func:`explained_fraction`, or an ``error`` where a comparison had no pixel; and
    ``"unexplained"``: per channel on which the fitted twin is beyond the ceiling, by how much
    and where (:func:`unexplained_residual`; empty when within it).
    """
    out: dict[str, Any] = {"nominal": None if nominal is None else _summary(nominal)}
    try:
        mask = build_mask(mask_spec, measured, fitted_object_id, object_names, turntable_ids)
        fitted = compare(measured, fitted_image, mask, (grey_full_scale, fitted_grey_full_scale))
        ceiling = compare(measured, second, mask, (grey_full_scale, grey_full_scale))
    except InvalidInputError as exc:
        out["error"] = str(exc)
        return out
    out["fitted"], out["ceiling"] = _summary(fitted), _summary(ceiling)
    # the objects (on the turntable, when any rides on it) as the fitted twin sees them
    regions = ({n: np.asarray(fitted_object_id) == i for i, n in enumerate(object_names)
                if i in turntable_ids or not turntable_ids}
               if fitted_object_id is not None else {})
    out["unexplained"] = unexplained_residual(
        measured, second, fitted_image, mask, (grey_full_scale, fitted_grey_full_scale),
        out["fitted"], out["ceiling"], regions, fitted_object_id)
    if nominal is not None:
        out["explained"] = {
            ch: explained_fraction(getattr(nominal, ch).mse, getattr(fitted, ch).mse,
                                   getattr(ceiling, ch).mse)
            for ch in ("depth", "grey")}
    return out


def _number(v: Any) -> float | None:
    """A figure of :func:`_summary` as a float (``"inf"`` and ``"nan"`` included), or None."""
    if isinstance(v, bool) or not isinstance(v, int | float | str):
        return None
    try:
        return float(v)
    except ValueError:
        return None


def beyond_ceiling(fitted: dict[str, Any], ceiling: dict[str, Any]) -> dict[str, str]:
    """The channels on which a fitted twin is beyond the noise ceiling (figures of
    :func:`_summary`), each with how much: depth RMSE above :data:`CEILING_DEPTH_RMSE_RATIO`
    times the ceiling's, grey PSNR more than :data:`CEILING_GREY_PSNR_DB` below it.

    >>> beyond_ceiling({"depth_rmse_m": 0.004, "grey_psnr_db": 30.0},
    ...                {"depth_rmse_m": 0.002, "grey_psnr_db": 30.5})
    {'depth': "depth RMSE 4.00 mm against the ceiling's 2.00 mm (2.00x)"}
    """
    out = {}
    d_fit, d_ceil = _number(fitted.get("depth_rmse_m")), _number(ceiling.get("depth_rmse_m"))
    if d_fit is not None and d_ceil is not None and d_fit > CEILING_DEPTH_RMSE_RATIO * d_ceil:
        # a zero ceiling (identical captures) makes any residual beyond it: no ratio to give
        ratio = f" ({d_fit / d_ceil:.2f}x)" if d_ceil > 0.0 else ""
        out["depth"] = (f"depth RMSE {1e3 * d_fit:.2f} mm against the ceiling's "
                        f"{1e3 * d_ceil:.2f} mm{ratio}")
    # a PSNR is "inf" (json_safe) for identical grey images: a perfect ceiling any twin is beyond
    g_fit, g_ceil = _number(fitted.get("grey_psnr_db")), _number(ceiling.get("grey_psnr_db"))
    if g_fit is not None and g_ceil is not None and g_fit < g_ceil - CEILING_GREY_PSNR_DB:
        out["grey"] = (f"grey PSNR {g_fit:.2f} dB against the ceiling's {g_ceil:.2f} dB "
                       f"({g_ceil - g_fit:.2f} dB below)")
    return out


def unexplained_residual(
    measured: ToFImage, second: ToFImage, fitted: ToFImage, mask: np.ndarray | None,
    grey_full_scales: tuple[float, float], fitted_figures: dict[str, Any],
    ceiling_figures: dict[str, Any], regions: dict[str, np.ndarray],
    object_id: np.ndarray | None = None,
) -> list[dict[str, Any]]:
    """Per channel on which the fitted twin is beyond the ceiling (:func:`beyond_ceiling`):
    what is left and where (:func:`sim_core.unexplained.locate_excess`), from the residual image
    (measured - fitted) against the ceiling's own (measured - second capture): range in mm,
    grey in the frames' 8-bit grey levels. ``regions``: the named objects' pixels (of the
    fitted twin). The sets tried are the fitted twin's silhouette edges (from its
    ``object_id`` image, :func:`sim_core.edges.object_edge_mask`; none without it) and the
    measured frame's dark pixels next to bright ones. Empty when the twin is within the ceiling.

    Each entry: ``{"channel", "by", "where": Location.to_dict(), "text"}``, where ``text`` reads
    "depth RMSE 3.10 mm against the ceiling's 1.20 mm (2.58x): a common offset of +2.9 mm over
    the turntable objects (92 % of the excess)".
    """
    channels = beyond_ceiling(fitted_figures, ceiling_figures)
    if not channels:
        return []
    fs_meas, fs_fit = grey_full_scales
    images = {
        "depth": (1e3 * (measured.range_m - fitted.range_m),
                  1e3 * (measured.range_m - second.range_m), "mm"),
        "grey": (metrics.grey_8bit(measured.amplitude, fs_meas).astype(float)
                 - metrics.grey_8bit(fitted.amplitude, fs_fit),
                 metrics.grey_8bit(measured.amplitude, fs_meas).astype(float)
                 - metrics.grey_8bit(second.amplitude, fs_meas), "grey levels"),
    }
    shape = measured.range_m.shape
    both = (np.ones(shape, bool) if mask is None else np.asarray(mask, bool))
    both = both & measured.valid & fitted.valid & second.valid
    sets = {"dark": dark_next_to_bright(measured.amplitude, measured.valid)}
    if object_id is not None:
        sets["edges"] = object_edge_mask(np.asarray(object_id))
    overall = "the compared pixels" if mask is None else "the compared objects"
    out = []
    for channel, by in channels.items():
        residual, noise, unit = images[channel]
        try:
            loc = locate_excess(residual, noise, both, unit=unit, overall=overall,
                                regions=regions, sets=sets)
        except InvalidInputError as exc:  # too few pixels to say where: said, not fatal
            out.append({"channel": channel, "by": by, "where": None,
                        "text": f"{by}: {exc}"})
            continue
        out.append({"channel": channel, "by": by, "where": loc.to_dict(),
                    "text": f"{by}: {loc.text()}"})
    return out


def load_measured(directory: str | Path) -> Frame:
    """A measured frame folder (:func:`sim_core.frame_io.read_measured`)."""
    return frame_io.read_measured(directory)


def load_simulated(directory: str | Path) -> Frame:
    """A simulated frame folder (:func:`sim_core.frame_io.read_simulated`)."""
    return frame_io.read_simulated(directory)
