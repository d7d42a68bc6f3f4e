"""Writing and reading frames: ``.npz`` arrays, a JSON sidecar, 16-bit PNG previews.

Every file is written to a temporary name in the target directory and renamed into place, so a
reader never sees a half-written file and a crash leaves at most a stray ``*.tmp``.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image


def _atomic_write(path: Path, write) -> None:
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write arrays (compressed) atomically."""
    _atomic_write(Path(path), lambda fh: np.savez_compressed(fh, **arrays))


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write JSON atomically (sorted keys, 2-space indent)."""
    text = json.dumps(data, indent=2, sort_keys=True, default=_json_default).encode()
    _atomic_write(Path(path), lambda fh: fh.write(text))


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def write_png(path: Path, image: np.ndarray) -> None:
    """Write a uint8 (8-bit grey) or uint16 (16-bit grey) image as PNG atomically."""
    if image.dtype not in (np.uint8, np.uint16):
        raise TypeError(f"PNG previews must be uint8 or uint16, got {image.dtype}")
    img = Image.fromarray(np.ascontiguousarray(image))
    _atomic_write(Path(path), lambda fh: img.save(fh, format="PNG"))


def depth_preview_mm(range_m: np.ndarray) -> np.ndarray:
    """16-bit depth image in millimetres, 0 where invalid (the camera tools' convention)."""
    mm = np.where(np.isfinite(range_m), np.round(range_m * 1000.0), 0.0)
    return np.clip(mm, 0, 65535).astype(np.uint16)


def grey_preview_8bit(value: np.ndarray, valid: np.ndarray, full_scale: float | None = None):
    """8-bit grey image: ``value / full_scale * 255``; full scale defaults to the 99.5th percentile.

    Returns the image and the full scale used.
    """
    if full_scale is None:
        sel = value[valid & np.isfinite(value)]
        full_scale = float(np.percentile(sel, 99.5)) if sel.size else 0.0
    if not full_scale > 0.0:
        return np.zeros(value.shape, dtype=np.uint8), 0.0
    g = np.where(np.isfinite(value), value, 0.0) / full_scale * 255.0
    return np.clip(np.round(g), 0, 255).astype(np.uint8), full_scale


def read_frame(directory: str | Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read ``frame.npz`` and ``frame.json`` from a frame directory."""
    d = Path(directory)
    with np.load(d / "frame.npz") as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads((d / "frame.json").read_text())
    return arrays, meta
