"""Comparing a measured and a simulated frame: masks, loading frame folders, Table 5 and the
figures a ToF engineer reads first.

The metrics themselves are :func:`sim_core.metrics.compare_images`: the seed's Table 5 rows and
(``tof``) the depth difference over the pixels valid in both frames and flying in neither
(median, median absolute deviation, 95th percentile of its magnitude, in mm) and the share of
flying and invalid pixels of each frame. This module decides which pixels count
(:class:`~service.lab.requests.MaskSpec`); frame folders are read by :mod:`sim_core.frame_io`.
Where a second capture of the same state exists (campaigns with an object fit), the same
figures of the measured frame against it are the noise ceiling (:func:`explained_difference`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from service.lab.requests import MaskSpec
from sim_core import frame_io, metrics
from sim_core.errors import InvalidInputError
from sim_core.frame_io import Frame
from sim_core.json_safe import json_safe
from sim_core.metrics import ComparisonReport
from sim_core.tof import ToFImage


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
    beat) and :func:`explained_fraction`, or an ``error`` where a comparison had no pixel.
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
    if nominal is not None:
        out["explained"] = {
            ch: explained_fraction(getattr(nominal, ch).mse, getattr(fitted, ch).mse,
                                   getattr(ceiling, ch).mse)
            for ch in ("depth", "grey")}
    return out


def load_measured(directory: str | Path) -> Frame:
    """A measured frame folder (:func:`sim_core.frame_io.read_measured`)."""
    return frame_io.read_measured(directory)


def load_simulated(directory: str | Path) -> Frame:
    """A simulated frame folder (:func:`sim_core.frame_io.read_simulated`)."""
    return frame_io.read_simulated(directory)
