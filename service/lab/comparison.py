"""Comparing a measured and a simulated frame: masks, loading frame folders, Table 5.

The metrics themselves are :func:`sim_core.metrics.compare_images`; this module decides which
pixels count (:class:`~service.api.schemas.MaskSpec`); frame folders are read by
:mod:`sim_core.frame_io`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from service.lab.requests import MaskSpec
from sim_core import frame_io, metrics
from sim_core.errors import InvalidInputError
from sim_core.frame_io import Frame
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


def load_measured(directory: str | Path) -> Frame:
    """A measured frame folder (:func:`sim_core.frame_io.read_measured`)."""
    return frame_io.read_measured(directory)


def load_simulated(directory: str | Path) -> Frame:
    """A simulated frame folder (:func:`sim_core.frame_io.read_simulated`)."""
    return frame_io.read_simulated(directory)
