"""A calibration's camera in other tools' forms (issue 29): OpenCV's FileStorage YAML and ROS's
``camera_info`` YAML.

The camera is the one the twin renders with a calibration file (:func:`calibrated_intrinsics`):
the file's lens keys, and for each key it does not hold, the pico flexx preset's. A file that
holds only part of the lens (only depth errors, say) gives the preset's values for the rest; a
file measured on an image of another size must hold all four of fx, fy, cx, cy, since the
preset's describe a 224 x 171 image.

- **OpenCV** (:func:`write_opencv_camera`): ``camera_matrix`` (3 x 3), ``distortion_coefficients``
  (1 x 5: k1, k2, p1, p2, k3), ``image_width``, ``image_height``, the keys OpenCV's own
  calibration sample writes and ``cv2.FileStorage(path, cv2.FILE_STORAGE_READ)`` reads.
- **ROS** (:func:`ros_camera_info`): the ``camera_info`` YAML of ROS's
  ``camera_calibration_parsers`` (what ``camera_info_manager`` loads): ``image_width``,
  ``image_height``, ``camera_name``, ``camera_matrix``, ``distortion_model: plumb_bob``,
  ``distortion_coefficients``, ``rectification_matrix`` (identity: a monocular camera) and
  ``projection_matrix`` (``[fx 0 cx 0; 0 fy cy 0; 0 0 1 0]``), each matrix as ``{rows, cols,
  data}`` in row-major order.

Pixel coordinates are OpenCV's (pixel centres at integers), which ROS's camera model shares.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from sim_core.camera import CAMERA_PRESETS, Intrinsics
from sim_core.errors import InvalidInputError
from sim_core.files import atomic_write
from sim_core.twin_file import TwinParameters

#: the camera a calibration file describes (its keys' defaults)
PRESET = "pmd-camboard-pico-flexx"
#: ``camera_name`` of a ROS camera_info file unless given
ROS_CAMERA_NAME = "pico_flexx"
#: a camera name camera_info_manager takes without a warning: letters, digits and underscores
ROS_CAMERA_NAME_PATTERN = r"[A-Za-z0-9_]{1,100}"
#: the forms :func:`write_camera_form` writes
FORMS = ("opencv", "ros")
#: the OpenCV form's name beside a calibration the calibration commands write
OPENCV_FILE = "opencv_intrinsics.yml"


def calibrated_intrinsics(cal: TwinParameters) -> Intrinsics:
    """The camera a twin renders with ``cal``: its lens keys, the preset's where it has none.

    >>> from sim_core.twin_file import parse_calibration
    >>> k = calibrated_intrinsics(parse_calibration({"camera": {"fx_px": 210.0}}))
    >>> (k.width_px, k.height_px, k.fx_px, k.fy_px == CAMERA_PRESETS[PRESET]["fy_px"])
    (224, 171, 210.0, True)
    """
    cam = cal.camera
    p = CAMERA_PRESETS[PRESET]
    lens = {"fx_px": cam.fx_px, "fy_px": cam.fy_px, "cx_px": cam.cx_px, "cy_px": cam.cy_px}
    if cam.image_size_px is not None and tuple(cam.image_size_px) != (p["width_px"],
                                                                      p["height_px"]):
        missing = [k for k, v in lens.items() if v is None]
        if missing:
            w, h = cam.image_size_px
            raise InvalidInputError(
                f"camera.{missing[0]}", f"absent, and the file's lens was measured on a {w} x "
                f"{h} image: the preset's value is for {p['width_px']} x {p['height_px']}; a "
                "calibration of another camera must hold fx_px, fy_px, cx_px and cy_px")
    width, height = (cam.image_size_px if cam.image_size_px is not None
                     else (p["width_px"], p["height_px"]))
    d = cam.distortion
    return Intrinsics(
        int(width), int(height),
        *(float(p[k] if v is None else v) for k, v in lens.items()),
        distortion=(0.0,) * 5 if d is None else (d.k1, d.k2, d.p1, d.p2, d.k3))


def camera_matrix(k: Intrinsics) -> np.ndarray:
    """The 3 x 3 camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` [px]."""
    return np.array([[k.fx_px, 0.0, k.cx_px], [0.0, k.fy_px, k.cy_px], [0.0, 0.0, 1.0]],
                    dtype=np.float64)


def opencv_camera_text(k: Intrinsics, extra: Mapping[str, Any] | None = None) -> str:
    """OpenCV's FileStorage YAML of camera ``k`` (module docstring) as text, with ``extra`` keys
    after (numbers, strings or arrays, as ``cv2.FileStorage.write`` takes them). (OpenCV is
    imported here: the service runs without it until a file in OpenCV's form is written.)"""
    import cv2

    fs = cv2.FileStorage(".yml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    fs.write("image_width", int(k.width_px))
    fs.write("image_height", int(k.height_px))
    fs.write("camera_matrix", camera_matrix(k))
    fs.write("distortion_coefficients", np.asarray(k.distortion, dtype=np.float64).reshape(1, 5))
    for name, value in (extra or {}).items():
        fs.write(name, value)
    return fs.releaseAndGetString()


def write_opencv_camera(path: str | Path, k: Intrinsics,
                        extra: Mapping[str, Any] | None = None) -> Path:
    """:func:`opencv_camera_text` written to ``path`` whole or not at all
    (:func:`sim_core.files.atomic_write`); the folder is made. Returns the path."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(p, opencv_camera_text(k, extra))


def ros_camera_info(k: Intrinsics, camera_name: str = ROS_CAMERA_NAME) -> dict[str, Any]:
    """ROS's camera_info YAML of camera ``k`` as a mapping (module docstring).

    >>> info = ros_camera_info(Intrinsics(224, 171, 210.0, 209.0, 112.5, 85.0))
    >>> info["distortion_model"], info["projection_matrix"]["data"][:4]
    ('plumb_bob', [210.0, 0.0, 112.5, 0.0])
    """
    def matrix(m: np.ndarray) -> dict[str, Any]:
        return {"rows": int(m.shape[0]), "cols": int(m.shape[1]),
                "data": [float(v) for v in m.ravel()]}

    kmat = camera_matrix(k)
    return {
        "image_width": int(k.width_px),
        "image_height": int(k.height_px),
        "camera_name": camera_name,
        "camera_matrix": matrix(kmat),
        "distortion_model": "plumb_bob",
        "distortion_coefficients": matrix(np.asarray(k.distortion, dtype=np.float64)
                                          .reshape(1, 5)),
        "rectification_matrix": matrix(np.eye(3)),
        "projection_matrix": matrix(np.hstack([kmat, np.zeros((3, 1))])),
    }


def write_camera_form(path: str | Path, cal: TwinParameters, form: str,
                      camera_name: str = ROS_CAMERA_NAME) -> Path:
    """Write calibration ``cal``'s camera (:func:`calibrated_intrinsics`) in ``form`` (one of
    :data:`FORMS`) to ``path``, whole or not at all (:func:`sim_core.files.atomic_write`);
    returns the path."""
    if form not in FORMS:
        raise InvalidInputError("--to", f"{form!r}; allowed: {', '.join(FORMS)}")
    k = calibrated_intrinsics(cal)
    text = (opencv_camera_text(k) if form == "opencv"
            else yaml.safe_dump(ros_camera_info(k, camera_name), sort_keys=False))
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write(p, text)
