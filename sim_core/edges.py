"""Depth error at depth edges: where a frame taken while the table turns differs most.

Motion during a frame smears the phases across the sub-frames (:mod:`sim_core.subframes`): the
pixels an edge crosses mix the phases of two surfaces. :func:`edge_mask` finds the pixels next
to a depth jump of the reference frame; :func:`edge_depth_error` the range difference there and
elsewhere, so a report can say how much of the error sits at the edges.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy import ndimage

from sim_core.errors import InvalidInputError

__all__ = ["EDGE_JUMP_M", "EdgeError", "edge_depth_error", "edge_mask", "object_edge_mask"]

#: a range jump between neighbouring pixels that makes an edge [m]
EDGE_JUMP_M = 0.05


def edge_mask(range_m: np.ndarray, valid: np.ndarray, jump_m: float = EDGE_JUMP_M,
              width_px: int = 1) -> np.ndarray:
    """Pixels within ``width_px`` of a range jump above ``jump_m`` to a 4-neighbour, or next to
    an invalid pixel (a silhouette against nothing), (H, W) bool.

    >>> r = np.ones((3, 6)); r[:, 3:] = 2.0
    >>> edge_mask(r, np.ones((3, 6), bool), width_px=0).astype(int)[0].tolist()
    [0, 0, 1, 1, 0, 0]
    """
    if not (np.isfinite(jump_m) and jump_m > 0.0):
        raise InvalidInputError("jump_m", f"got {jump_m!r}; allowed: a finite range > 0 m")
    if not (isinstance(width_px, int) and 0 <= width_px <= 20):
        raise InvalidInputError("width_px", f"got {width_px!r}; allowed: 0 to 20 px")
    ok = np.asarray(valid, bool) & np.isfinite(range_m)
    r = np.where(ok, range_m, np.nan)
    # NaN (an invalid neighbour) counts as a jump: the silhouette of what is measured
    return _both_sides(lambda axis: ~(np.abs(np.diff(r, axis=axis)) <= jump_m), r.shape,
                       width_px) & ok


def _both_sides(differs, shape: tuple[int, ...], width_px: int) -> np.ndarray:
    """Both pixels of every 4-neighbour pair ``differs(axis)`` flags (a bool image one shorter
    along ``axis``), widened by ``width_px`` (binary dilation), (H, W) bool."""
    marked = np.zeros(shape, bool)
    for axis in (0, 1):
        flagged = differs(axis)
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        marked[tuple(lo)] |= flagged
        marked[tuple(hi)] |= flagged
    if width_px > 0:
        marked = ndimage.binary_dilation(marked, iterations=width_px)
    return marked


def object_edge_mask(object_id: np.ndarray, width_px: int = 1) -> np.ndarray:
    """Pixels within ``width_px`` of a 4-neighbour that sees another object (or nothing, id < 0)
    in a simulator's object-id image: the silhouettes as the twin draws them, free of the range
    noise that makes a measured frame's jumps (:func:`edge_mask`) fire on noisy pixels,
    (H, W) bool.

    >>> ids = np.zeros((3, 6), int); ids[:, 3:] = 1
    >>> object_edge_mask(ids, width_px=0).astype(int)[0].tolist()
    [0, 0, 1, 1, 0, 0]
    """
    ids = np.asarray(object_id)
    if ids.ndim != 2 or not np.issubdtype(ids.dtype, np.integer):
        raise InvalidInputError("object_id", f"got a {ids.dtype} array of shape {ids.shape}; "
                                "allowed: a 2-D integer image")
    if not (isinstance(width_px, int) and 0 <= width_px <= 20):
        raise InvalidInputError("width_px", f"got {width_px!r}; allowed: 0 to 20 px")
    return _both_sides(lambda axis: np.diff(ids, axis=axis) != 0, ids.shape, width_px)


@dataclass(frozen=True)
class EdgeError:
    """Range difference (measured - simulated) at the edges and away from them [mm]."""

    edge_pixels: int
    interior_pixels: int
    edge_median_abs_mm: float | None
    edge_rms_mm: float | None
    interior_median_abs_mm: float | None
    interior_rms_mm: float | None

    def to_dict(self) -> dict:
        return asdict(self)


def _stats_mm(d_m: np.ndarray) -> tuple[float | None, float | None]:
    if d_m.size == 0:  # no pixel: no statistic (not 0, which would read as perfect)
        return None, None
    return float(np.median(np.abs(d_m)) * 1e3), float(np.sqrt(np.mean(d_m**2)) * 1e3)


def edge_depth_error(measured_range_m: np.ndarray, simulated_range_m: np.ndarray,
                     mask: np.ndarray, reference_valid: np.ndarray,
                     jump_m: float = EDGE_JUMP_M, edges: np.ndarray | None = None) -> EdgeError:
    """The range difference inside ``mask`` split into edge pixels (of the simulated frame:
    :func:`edge_mask`; or ``edges`` when given, to compare two simulations on the same pixels)
    and the rest."""
    both = (np.asarray(mask, bool) & np.isfinite(measured_range_m)
            & np.isfinite(simulated_range_m))
    if edges is None:
        edges = edge_mask(simulated_range_m, reference_valid, jump_m)
    edges = np.asarray(edges, bool) & both
    interior = both & ~edges
    d = measured_range_m - simulated_range_m
    e_med, e_rms = _stats_mm(d[edges])
    i_med, i_rms = _stats_mm(d[interior])
    return EdgeError(int(edges.sum()), int(interior.sum()), e_med, e_rms, i_med, i_rms)
