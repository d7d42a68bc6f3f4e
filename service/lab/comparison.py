"""Comparing a measured and a simulated frame: masks, loading frame folders, Table 5.

The metrics themselves are :func:`sim_core.metrics.compare_images`; this module decides which
pixels count (:class:`~service.api.schemas.MaskSpec`) and reads frames back from their folders.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from service.lab.requests import MaskSpec
from sim_core import metrics
from sim_core.camera import CAMERA_PRESETS, Intrinsics
from sim_core.errors import InvalidInputError
from sim_core.metrics import ComparisonReport
from sim_core.raw import RawFrame, reconstruct_raw
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
) -> ComparisonReport:
    """Seed Table 5 indexes of ``simulated`` against ``measured`` inside ``mask``."""
    return metrics.compare_images(measured, simulated, mask)


# -- frame folders ---------------------------------------------------------------------------
def _meta(directory: Path) -> dict:
    p = directory / "frame.json"
    return json.loads(p.read_text()) if p.is_file() else {}


def _intrinsics(meta: dict, shape: tuple[int, int]) -> Intrinsics:
    if "intrinsics" in meta:
        i = meta["intrinsics"]
        return Intrinsics(
            i["width_px"], i["height_px"], i["fx_px"], i["fy_px"], i["cx_px"], i["cy_px"],
            tuple(i.get("distortion", (0.0,) * 5)),
        )
    # no intrinsics recorded: the pico flexx preset, principal point at the image centre
    p = CAMERA_PRESETS["pmd-camboard-pico-flexx"]
    h, w = shape
    return Intrinsics(w, h, p["fx_px"], p["fy_px"], (w - 1) / 2.0, (h - 1) / 2.0)


def load_measured(directory: str | Path) -> ToFImage:
    """Reconstruct ``raw.npz`` of a measured frame folder with :func:`reconstruct_raw`."""
    from sim_core.camera import pixel_centre_grid, pixel_to_camera_direction

    d = Path(directory)
    if not (d / "raw.npz").is_file():
        raise InvalidInputError("measured_dir", f"'{d}' holds no raw.npz (a measured frame)")
    raw = RawFrame.load(d / "raw.npz")
    intr = _intrinsics(_meta(d), raw.shape)
    if intr.shape != raw.shape:
        raise InvalidInputError(
            "measured_dir", f"raw frame is {raw.shape} but frame.json intrinsics {intr.shape}"
        )
    u, v = pixel_centre_grid(intr)
    z_over_range = pixel_to_camera_direction(intr, u, v)[:, 2].reshape(intr.shape)
    return reconstruct_raw(raw, z_over_range)


def load_simulated(directory: str | Path) -> tuple[ToFImage, dict[str, np.ndarray], dict]:
    """A simulated frame folder (``save_frame`` layout): its image, arrays and metadata."""
    d = Path(directory)
    if not (d / "frame.npz").is_file():
        raise InvalidInputError("simulated_dir", f"'{d}' holds no frame.npz (a saved frame)")
    with np.load(d / "frame.npz") as z:
        arrays = {k: z[k] for k in z.files}
    image = image_from_arrays(arrays)
    return image, arrays, _meta(d)


def image_from_arrays(arrays: dict[str, np.ndarray]) -> ToFImage:
    """A :class:`ToFImage` from the arrays of a ``frame.npz``."""
    phase = arrays.get("phase_all_rad", arrays["phase_rad"][None])
    return ToFImage(
        range_m=arrays["range_m"],
        depth_z_m=arrays["depth_z_m"],
        amplitude=arrays["amplitude"],
        intensity=arrays["intensity"],
        phase_rad=phase,
        valid=arrays["valid"].astype(bool),
        frequencies_hz=arrays["frequencies_hz"],
    )
