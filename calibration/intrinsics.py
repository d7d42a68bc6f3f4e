"""Intrinsics and distortion from board views (OpenCV ``calibrateCamera``).

The views are calibrated together; views whose own reprojection RMS is an outlier (more than
:data:`OUTLIER_FACTOR` times the median and above :data:`OUTLIER_FLOOR_PX`) are rejected with
the reason and the rest calibrated again. Before trusting a result the views' spread is checked:
boards that are all parallel to one line (every board containing the turntable's axis) are a
degenerate set for planar calibration (Sturm & Maybank 1999): the smallest singular value of
the stacked board normals must not vanish. k3 is held at 0: at 224 x 171 pixels and this field
of view the sixth-order term is not determined separately from k1 and k2 (it trades off
against them), so fitting it only adds variance.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from calibration.board_views import BoardView
from sim_core.camera import CAMERA_PRESETS, Intrinsics
from sim_core.errors import InvalidInputError

MIN_VIEWS = 6
MIN_CORNERS_PER_VIEW = 6
OUTLIER_FACTOR = 3.0
OUTLIER_FLOOR_PX = 0.5
#: smallest singular value of the unit board normals (over sqrt(views)) below which the views
#: are parallel to one line
MIN_NORMAL_SPREAD = 0.08
#: a view's corners must span the board's plane: the smaller singular value of their centred
#: board coordinates at least this fraction of the larger (0: all on one line, whose homography,
#: OpenCV's start, does not exist)
MIN_CORNER_SPAN_RATIO = 0.05


def corner_span_ratio(object_points_m: np.ndarray) -> float:
    """How far a view's corners span the board's plane: the smaller over the larger singular
    value of their centred board coordinates (x, y) [-]; 0 for corners on one line or fewer
    than three.

    >>> corner_span_ratio(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]))
    0.0
    >>> round(corner_span_ratio(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0]])), 3)
    1.0
    """
    xy = np.asarray(object_points_m, dtype=np.float64).reshape(len(object_points_m), -1)[:, :2]
    if len(xy) < 3:
        return 0.0
    s = np.linalg.svd(xy - xy.mean(axis=0), compute_uv=False)
    return 0.0 if not s[0] > 0.0 else float(s[1] / s[0])


def _unusable_reason(view: BoardView) -> str | None:
    """Why ``view`` cannot enter a calibration (too few corners, corners on one line), or
    None."""
    if len(view.corner_ids) < MIN_CORNERS_PER_VIEW:
        return f"{len(view.corner_ids)} corners (fewer than {MIN_CORNERS_PER_VIEW})"
    span = corner_span_ratio(view.object_points_m)
    if span < MIN_CORNER_SPAN_RATIO:
        return (f"its {len(view.corner_ids)} corners lie on one line (span ratio {span:.3f}, "
                f"needs {MIN_CORNER_SPAN_RATIO}): a view must show at least two rows and two "
                "columns of corners")
    return None


@dataclass(frozen=True)
class IntrinsicsResult:
    """Calibrated intrinsics, their uncertainty, residuals and the board poses.

    Attributes
    ----------
    intrinsics : Intrinsics
    std : dict
        Standard deviations of fx, fy, cx, cy, k1, k2, p1, p2 (OpenCV's estimate).
    rms_px : float
        Reprojection RMS over all used corners.
    per_view_rms_px : dict
        View name -> its RMS.
    poses : dict
        View name -> (rvec (3,), tvec (3,)): the board frame in the camera frame.
    rejected : list of dict
        ``{"name", "reason"}`` of the views not used.
    normal_spread : float
        The spread measure of the board normals (see module docstring).
    n_corners : int
    refined_with_turntable : bool
        True when ``intrinsics``, ``rms_px`` and ``poses`` come from the bundle adjustment of
        camera and turntable together (:func:`calibration.turntable_axis.fit_turntable_axis`),
        False when from OpenCV's free-pose calibration (``std`` and the per-view RMS always
        are).
    """

    intrinsics: Intrinsics
    std: dict[str, float]
    rms_px: float
    per_view_rms_px: dict[str, float]
    poses: dict[str, tuple[np.ndarray, np.ndarray]] = field(repr=False)
    rejected: list[dict[str, str]]
    normal_spread: float
    n_corners: int
    refined_with_turntable: bool = False

    def summary(self) -> dict:
        k = self.intrinsics
        return {"fx_px": k.fx_px, "fy_px": k.fy_px, "cx_px": k.cx_px, "cy_px": k.cy_px,
                "distortion": list(k.distortion), "std": self.std, "rms_px": self.rms_px,
                "views": len(self.per_view_rms_px), "corners": self.n_corners,
                "worst_view_rms_px": max(self.per_view_rms_px.values()),
                "normal_spread": self.normal_spread, "rejected": self.rejected,
                "refined_with_turntable": self.refined_with_turntable}

    def plot(self, ax) -> str:
        names = list(self.per_view_rms_px)
        ax.bar(range(len(names)), [self.per_view_rms_px[n] for n in names])
        ax.set_xlabel("view")
        ax.set_ylabel("reprojection RMS [px]")
        ax.axhline(self.rms_px, color="k", lw=0.8)
        return f"Reprojection RMS per view (all: {self.rms_px:.3f} px)"


def _calibrate(views, shape, guess, fix_k3: bool = True, zero_tangential: bool = False):
    """OpenCV's calibration of ``views``; ``guess`` None: OpenCV's own start from the views'
    homographies (a camera with no preset)."""
    obj = [v.object_points_m.astype(np.float32) for v in views]
    img = [v.image_points_px.astype(np.float32).reshape(-1, 1, 2) for v in views]
    h, w = shape
    flags = (cv2.CALIB_FIX_K3 if fix_k3 else 0) | (
        cv2.CALIB_ZERO_TANGENT_DIST if zero_tangential else 0)
    k = None
    if guess is not None:
        k = np.array([[guess["fx_px"], 0, guess["cx_px"]], [0, guess["fy_px"], guess["cy_px"]],
                      [0, 0, 1]], dtype=np.float64)
        flags |= cv2.CALIB_USE_INTRINSIC_GUESS
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    rms, k, d, rvecs, tvecs, std_in, _, per_view = cv2.calibrateCameraExtended(
        obj, img, (w, h), k, np.zeros(5), flags=flags, criteria=crit)
    return rms, k, d.ravel(), rvecs, tvecs, std_in.ravel(), per_view.ravel()


def normal_spread(rvecs) -> float:
    """Smallest singular value of the stacked board normals over sqrt(n) (0: degenerate)."""
    normals = np.array([cv2.Rodrigues(np.asarray(r, dtype=np.float64))[0][:, 2] for r in rvecs])
    return float(np.linalg.svd(normals, compute_uv=False)[-1] / np.sqrt(len(normals)))


def calibrate_intrinsics(views: list[BoardView], image_shape: tuple[int, int],
                         preset: str = "pmd-camboard-pico-flexx", *, fix_k3: bool = True,
                         guess_from_preset: bool = True,
                         refuse_degenerate: bool = True,
                         zero_tangential: bool = False) -> IntrinsicsResult:
    """Calibrate from the views (module docstring); raises :class:`InvalidInputError` when the
    views are too few, too sparse or degenerate.

    The defaults are the ToF camera's procedure. A camera of another kind (a photo camera,
    :mod:`calibration.photo_intrinsics`) may fit k3 (``fix_k3=False``: its standard deviation
    is then in ``std``), start from OpenCV's own estimate from the views' homographies instead
    of the preset (``guess_from_preset=False``), and get degenerate views back as a result
    (``refuse_degenerate=False``: ``normal_spread`` below :data:`MIN_NORMAL_SPREAD`, for its
    verdicts to say so) rather than as an error; and hold the tangential terms p1, p2 at 0
    (``zero_tangential``: they are then absent from ``std``) when the views do not call for
    them.
    """
    reasons = {id(v): _unusable_reason(v) for v in views}
    rejected = [{"name": v.name, "reason": reasons[id(v)]} for v in views if reasons[id(v)]]
    use = [v for v in views if reasons[id(v)] is None]
    if len(use) < MIN_VIEWS:
        raise InvalidInputError(
            "intrinsics.views",
            f"the board was detected in {len(use)} usable views (enough corners, not on one "
            f"line); at least "
            f"{MIN_VIEWS} are needed: check the board is in view, lit and in focus, or add "
            "views (more turntable angles, another fixture)")
    guess = CAMERA_PRESETS[preset] if guess_from_preset else None
    while True:
        rms, k, d, rvecs, tvecs, std, per_view = _calibrate(use, image_shape, guess, fix_k3,
                                                             zero_tangential)
        med = float(np.median(per_view))
        worst = int(np.argmax(per_view))
        limit = max(OUTLIER_FACTOR * med, OUTLIER_FLOOR_PX)
        if per_view[worst] <= limit or len(use) <= MIN_VIEWS:
            break
        rejected.append({"name": use[worst].name,
                         "reason": f"reprojection RMS {per_view[worst]:.2f} px, more than "
                                   f"{limit:.2f} px ({OUTLIER_FACTOR:g} x the median)"})
        use = use[:worst] + use[worst + 1:]
    spread = normal_spread(rvecs)
    if spread < MIN_NORMAL_SPREAD and refuse_degenerate:
        raise InvalidInputError(
            "intrinsics.views",
            f"the board normals are all nearly parallel to one plane (spread {spread:.3f}, "
            f"needs {MIN_NORMAL_SPREAD}): boards that all contain the turntable's axis are a "
            "degenerate set; mount the board tilted, in at least two fixtures (e.g. +30 and "
            "-30 deg)")
    intr = Intrinsics(image_shape[1], image_shape[0], float(k[0, 0]), float(k[1, 1]),
                      float(k[0, 2]), float(k[1, 2]), tuple(float(x) for x in d[:5]))
    names = ("fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "p1", "p2") + (
        () if fix_k3 else ("k3",))
    held = ("p1", "p2") if zero_tangential else ()
    return IntrinsicsResult(
        intrinsics=intr, std={n: float(s) for n, s in zip(names, std, strict=False)
                              if n not in held},
        rms_px=float(rms), per_view_rms_px={v.name: float(r) for v, r in zip(use, per_view,
                                                                              strict=True)},
        poses={v.name: (np.asarray(r, dtype=np.float64).ravel(),
                        np.asarray(t, dtype=np.float64).ravel())
               for v, r, t in zip(use, rvecs, tvecs, strict=True)},
        rejected=rejected, normal_spread=spread,
        n_corners=int(sum(len(v.corner_ids) for v in use)))
