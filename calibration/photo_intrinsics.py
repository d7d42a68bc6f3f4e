"""Intrinsics and distortion from a user's own board images (``toftwin calibrate intrinsics``).

Images in, intrinsics, a per-view report and verdicts out. Any camera, any image size:

- **images**: 8 or 16-bit PNG, JPEG, TIFF (colour is converted to grey), and the project's
  frame folders (``frame.npz``, read with :func:`sim_core.frame_io.read_frame`: the amplitude);
  a folder argument is every supported image and frame folder in it, sorted by name; a folder
  holding ``frame.npz`` or ``raw.npz`` is one frame.
- **boards**: ``--squares WxH`` counts SQUARES (the ChArUco convention), so a chessboard of
  10 x 7 squares has 9 x 6 inner corners (OpenCV's ``patternSize``); ChArUco boards take their
  marker side and ArUco dictionary. The corners are in OpenCV's board frame
  (:func:`sim_core.boards.board_corners_m`) [m].
- **detection**: images with a shorter side of at most :data:`SMALL_IMAGE_PX` (the ToF camera's
  224 x 171) go to the project's detector for low-resolution amplitude images
  (:func:`calibration.board_detection.detect_board`: upscaled, saddle-refined); larger ones to
  OpenCV's own detectors at their resolution: ``findChessboardCorners`` and ``cornerSubPix``
  (``findChessboardCornersSB`` when that fails), ``cv2.aruco.CharucoDetector`` for ChArUco.
- **calibration**: :func:`calibration.intrinsics.calibrate_intrinsics` (OpenCV's
  ``calibrateCameraExtended``, outlier views rejected with the reason), started from the
  views' homographies; k3 held at 0 unless asked for (``fit_k3``).
- **tangential terms only when the views call for them**: p1 and p2 trade off against the
  principal point (a decentred lens and a shifted centre bend the corners alike), so fitting
  them where the lens has next to none spends the views' information on noise: on rendered views
  of a ToF camera whose p1, p2 are 1e-4, freeing them left the residual unchanged (0.102 px
  either way) and moved cx by 0.8 px. The calibration is done both ways on the same views, and
  the extra-sum-of-squares F test decides (:data:`TANGENTIAL_P_VALUE`); held at 0, p1 and p2 are
  written as 0 and their verdicts say ``not determined`` with the test's figures. Holding them
  is an assumption the views could not refute, not a measurement: every other parameter's
  standard deviation then adds, in quadrature, how far it moved between the two fits (on eleven
  random realities this kept every principal point within 2.5 of its standard deviations,
  where the held fit's own spread alone left two 5 apart).

The verdicts (:mod:`calibration.verdicts`), one per written key (``camera.fx_px`` ...
``camera.distortion.p2``):

- **explained**: the lens model must explain the corners. Reprojection residuals that depend
  on where a corner is in the image are the model's error; those that differ from view to view
  are the corners' noise (detection, print, a board not quite flat). The image is cut into
  :data:`CELL_GRID` cells; in each cell every view's residuals are averaged (one value per view
  and cell), and the cells' mean residuals are compared with the spread of their views'
  values: ``chi2 = sum_c n_c |mean_c|^2 / (2 C s^2)`` with ``s^2`` the pooled within-cell
  variance (per coordinate) and ``n_c`` the views in cell ``c`` (cells with at least
  :data:`MIN_VIEWS_PER_CELL`). About 1 when the model explains the corners; above
  :func:`calibration.verdicts.chi2_limit_for` its degrees of freedom every key is
  ``unexplained`` (e.g. a wide-angle lens whose k3 is held at 0).
- **standard deviation**: OpenCV's ``stdDeviationsIntrinsics`` (from the Jacobian at the
  residual's own variance, per coordinate, since OpenCV 4.7: already as large as the residual
  says), never below the delete-one-view jackknife's spread (:func:`calibration.rig_verdicts.
  jackknife_std`; each view's leave-out by one Gauss-Newton step from the full fit,
  :func:`one_step_leave_outs`, not by a new calibration, which can run off).
- **limits**: the ToF camera's targets (:data:`calibration.rig_verdicts.FOCAL_REL`, 0.5 % of
  the focal length; :data:`~calibration.rig_verdicts.PRINCIPAL_POINT_PX`, 0.5 px; distortion
  moving a corner by :data:`~calibration.rig_verdicts.REPROJECTION_PX`, 0.3 px) taken as
  angles, so that they ask the same of every camera: a principal point off by 0.5 px at the
  pico flexx's 208 px focal length tilts the optical axis by 2.4 mrad, which is 1.3 px at a
  533 px focal length. Pixel limits scale by ``max(1, f / 208.33)`` (never tighter in pixels
  than the ToF camera's); the focal length's is relative already.
- **degenerate views**: boards whose normals are all parallel to one plane
  (:func:`calibration.intrinsics.normal_spread` below
  :data:`~calibration.intrinsics.MIN_NORMAL_SPREAD`) do not determine the intrinsics: every key
  ``not determined`` with the reason.

Frames and units: pixel coordinates in OpenCV's pixel-centre convention (pixel centres at
integers), focal lengths and principal point [px], distortion OpenCV's (k1, k2, p1, p2, k3)
[1], board points [m].
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
from scipy import stats

from calibration.board_detection import BoardDetection, detect_board, to_8bit
from calibration.board_views import BoardView
from calibration.camera_forms import OPENCV_FILE, write_opencv_camera
from calibration.intrinsics import (
    MIN_CORNERS_PER_VIEW,
    MIN_NORMAL_SPREAD,
    MIN_VIEWS,
    IntrinsicsResult,
    calibrate_intrinsics,
)
from calibration.rig_verdicts import (
    FOCAL_REL,
    PRINCIPAL_POINT_PX,
    StageEvidence,
    distortion_limit,
    jackknife_std,
)
from calibration.verdicts import Verdict, Verdicts, chi2_limit_for
from sim_core.camera import CAMERA_PRESETS
from sim_core.errors import InvalidInputError

BoardKind = Literal["charuco", "chessboard"]
BOARD_KINDS: tuple[str, ...] = ("charuco", "chessboard")
#: image files read (lower-case suffixes)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff")
#: the frame format's array file (a frame folder's reconstruction)
FRAME_NPZ = "frame.npz"
#: images whose shorter side is at most this go to the project's low-resolution detector [px]
SMALL_IMAGE_PX = 320
#: the shorter side the low-resolution detector upscales to, at least [px]
UPSCALED_PX = 480
#: the cells the image is cut into for the model test: rows, columns
CELL_GRID = (6, 8)
#: views a cell needs to count in the model test
MIN_VIEWS_PER_CELL = 3
#: the tangential terms p1, p2 are fitted when freeing them reduces the residual this unlikely
#: by chance (the F test's p-value; module docstring)
TANGENTIAL_P_VALUE = 0.01
#: squares a side a board may have
SQUARES_RANGE = (3, 40)
#: the focal length the ToF targets are set at [px] (the pico flexx's)
REFERENCE_FOCAL_PX = float(CAMERA_PRESETS["pmd-camboard-pico-flexx"]["fx_px"])


# -- the board -------------------------------------------------------------------------------
@dataclass(frozen=True)
class PhotoBoard:
    """The board the images show.

    Attributes
    ----------
    kind : "charuco" or "chessboard"
    squares_x, squares_y : int
        Squares along the board's x (its width as drawn) and y; a chessboard's inner corners
        are one fewer each.
    square_m : float
        Side of a square [m].
    marker_m : float or None
        Side of a ChArUco marker [m].
    dictionary : str or None
        The ChArUco board's ArUco dictionary (``DICT_4X4_50`` ...).
    """

    kind: BoardKind
    squares_x: int
    squares_y: int
    square_m: float
    marker_m: float | None = None
    dictionary: str | None = None

    @property
    def mesh(self):
        """The board as the project's mesh spec (what :mod:`sim_core.boards` and the detector
        take)."""
        from sim_core.scene_spec import CharucoBoardMesh, CheckerboardMesh

        if self.kind == "chessboard":
            return CheckerboardMesh(kind="checkerboard", squares_x=self.squares_x,
                                    squares_y=self.squares_y, square_m=self.square_m)
        return CharucoBoardMesh(kind="charuco_board", squares_x=self.squares_x,
                                squares_y=self.squares_y, square_m=self.square_m,
                                marker_m=self.marker_m, dictionary=self.dictionary)

    def describe(self) -> str:
        what = (f"chessboard of {self.squares_x} x {self.squares_y} squares "
                f"({self.squares_x - 1} x {self.squares_y - 1} inner corners)")
        if self.kind == "charuco":
            what = (f"ChArUco board of {self.squares_x} x {self.squares_y} squares, "
                    f"{self.dictionary}, markers {self.marker_m * 1e3:g} mm")
        return f"{what}, squares {self.square_m * 1e3:g} mm"


def parse_squares(text: str, field_name: str = "--squares") -> tuple[int, int]:
    """``"10x7"`` -> (10, 7): squares along x and y, each in :data:`SQUARES_RANGE`.

    >>> parse_squares("10x7")
    (10, 7)
    """
    m = re.fullmatch(r"\s*(\d+)\s*[xX*]\s*(\d+)\s*", text or "")
    lo, hi = SQUARES_RANGE
    if m is None:
        raise InvalidInputError(field_name, f"{text!r} is not WxH (squares across x down, e.g. "
                                f"10x7); each {lo}-{hi}")
    sx, sy = int(m.group(1)), int(m.group(2))
    for n, side in ((sx, "W"), (sy, "H")):
        if not lo <= n <= hi:
            raise InvalidInputError(field_name, f"{side} = {n} squares; allowed: {lo}-{hi} "
                                    "(squares, not inner corners: a 9 x 6 inner-corner "
                                    "chessboard is 10x7)")
    return sx, sy


def make_board(kind: str, squares: str, square_mm: float, marker_mm: float | None = None,
               dictionary: str | None = None) -> PhotoBoard:
    """The board of the command's options; errors name the option and the allowed values."""
    from sim_core.boards import board_problem, dictionary_names

    if kind not in BOARD_KINDS:
        raise InvalidInputError("--board", f"{kind!r}; allowed: {', '.join(BOARD_KINDS)}")
    sx, sy = parse_squares(squares)
    if not (math.isfinite(square_mm) and square_mm > 0.0):
        raise InvalidInputError("--square-mm", f"{square_mm:g}; allowed: a side above 0 mm")
    if kind == "chessboard":
        return PhotoBoard("chessboard", sx, sy, square_mm * 1e-3)
    if marker_mm is None:
        raise InvalidInputError("--marker-mm", "a ChArUco board needs its marker side [mm]")
    if not (math.isfinite(marker_mm) and 0.0 < marker_mm < square_mm):
        raise InvalidInputError("--marker-mm", f"{marker_mm:g}; allowed: above 0 and below "
                                f"--square-mm ({square_mm:g} mm)")
    names = dictionary_names()
    if dictionary is None or dictionary not in names:
        raise InvalidInputError("--dictionary", f"{dictionary!r}; allowed: {', '.join(names)}")
    board = PhotoBoard("charuco", sx, sy, square_mm * 1e-3, marker_mm * 1e-3, dictionary)
    problem = board_problem(board.mesh)
    if problem is not None:
        raise InvalidInputError("--squares/--marker-mm/--dictionary", problem)
    return board


# -- the images ------------------------------------------------------------------------------
def _is_frame_folder(path: Path) -> bool:
    return path.is_dir() and ((path / FRAME_NPZ).is_file() or (path / "raw.npz").is_file())


def image_sources(arguments: Sequence[str | Path], field_name: str = "IMAGES") -> list[Path]:
    """The images the arguments name: files as given, a frame folder (or its ``frame.npz``) as
    one frame, any other folder as every supported image and frame folder in it, sorted by
    name. Missing paths, unsupported files and folders without images are errors naming
    ``field_name``."""
    out: list[Path] = []
    allowed = ", ".join(IMAGE_SUFFIXES) + f", {FRAME_NPZ} or a frame folder"
    for arg in arguments:
        p = Path(arg)
        if not p.exists():
            raise InvalidInputError(field_name, f"'{p}' does not exist")
        if _is_frame_folder(p):
            out.append(p)
        elif p.is_dir():
            found = sorted((q for q in p.iterdir()
                            if (q.is_file() and q.suffix.lower() in IMAGE_SUFFIXES)
                            or _is_frame_folder(q)), key=lambda q: q.name)
            if not found:
                raise InvalidInputError(field_name, f"folder '{p}' holds no image ({allowed})")
            out.extend(found)
        elif p.name == FRAME_NPZ:
            out.append(p.parent)
        elif p.suffix.lower() in IMAGE_SUFFIXES:
            out.append(p)
        else:
            raise InvalidInputError(field_name, f"'{p}' is not a supported image; allowed: "
                                    f"{allowed}")
    if not out:
        raise InvalidInputError(field_name, f"no images given ({allowed})")
    return out


def load_grey(path: str | Path) -> np.ndarray:
    """The grey image at ``path`` (H, W): uint8, uint16 or float32 as stored (colour converted
    with OpenCV's BGR weights); a frame folder's amplitude (float, DN or the ideal sensor's
    unit, NaN where not valid). Unreadable files are errors naming the file."""
    p = Path(path)
    if p.is_dir():
        from sim_core.frame_io import read_frame

        try:
            frame = read_frame(p)
        except (OSError, ValueError, KeyError) as exc:
            raise InvalidInputError(str(p), f"not a readable frame folder: {exc}") from None
        return np.asarray(frame.image.amplitude, dtype=np.float64)
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH)
    if img is None:
        raise InvalidInputError(str(p), "not a readable image (8 or 16-bit PNG, JPEG, TIFF)")
    if img.ndim == 3:
        code = {3: cv2.COLOR_BGR2GRAY, 4: cv2.COLOR_BGRA2GRAY}.get(img.shape[2])
        img = img[:, :, 0] if code is None else cv2.cvtColor(img, code)
    return img


def to_detector_8bit(grey: np.ndarray) -> np.ndarray:
    """An 8-bit image for OpenCV's detectors: 8-bit images as they are, deeper ones stretched
    between robust percentiles (:func:`calibration.board_detection.to_8bit`)."""
    return grey if grey.dtype == np.uint8 else to_8bit(grey)


# -- detection -------------------------------------------------------------------------------
def detect_corners(grey: np.ndarray, board: PhotoBoard) -> BoardDetection | None:
    """The board's corners in ``grey`` (H, W), or None when the board is not found
    (module docstring: which detector for which image size)."""
    from sim_core.boards import board_corners_m

    h, w = grey.shape
    if min(h, w) <= SMALL_IMAGE_PX:
        upscale = max(2, math.ceil(UPSCALED_PX / min(h, w)))
        return detect_board(np.asarray(grey, dtype=np.float64), board.mesh, upscale=upscale,
                            min_corners=1)
    img = to_detector_8bit(grey)
    pts, _ = board_corners_m(board.mesh)
    if board.kind == "chessboard":
        xy = _chessboard(img, board)
        if xy is None:
            return None
        return BoardDetection(pts, xy, np.arange(len(pts)), (h, w))
    from sim_core.boards import cv2_board

    detector = cv2.aruco.CharucoDetector(cv2_board(board.mesh))
    corners, ids, _, _ = detector.detectBoard(img)
    if ids is None or len(ids) == 0:
        return None
    ids = ids.ravel().astype(int)
    return BoardDetection(pts[ids], corners.reshape(-1, 2).astype(np.float64), ids, (h, w))


def _chessboard(img: np.ndarray, board: PhotoBoard) -> np.ndarray | None:
    """All inner corners (row by row along x) [px], or None: ``findChessboardCorners`` with
    ``cornerSubPix`` (OpenCV's calibration sample and test), else ``findChessboardCornersSB``."""
    size = (board.squares_x - 1, board.squares_y - 1)
    n = size[0] * size[1]
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, found = cv2.findChessboardCorners(img, size, flags=flags)
    if ok and found is not None and len(found) == n:
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.01)
        found = cv2.cornerSubPix(img, found.astype(np.float32), (5, 5), (-1, -1), crit)
        return found.reshape(-1, 2).astype(np.float64)
    ok, found = cv2.findChessboardCornersSB(
        img, size, flags=cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE
        | cv2.CALIB_CB_EXHAUSTIVE)
    if ok and found is not None and len(found) == n:
        return found.reshape(-1, 2).astype(np.float64)
    return None


# -- the per-view report and the result ------------------------------------------------------
@dataclass(frozen=True)
class ViewReport:
    """One image: its corners, and either its reprojection RMS or why it was not used.

    ``rms_px`` is the view's reprojection RMS [px] in the final calibration (None when not
    used); ``reason`` why it was refused (None when used).
    """

    name: str
    path: str
    corners: int
    rms_px: float | None = None
    reason: str | None = None

    @property
    def used(self) -> bool:
        return self.reason is None

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "path": self.path, "corners": self.corners,
                "rms_px": self.rms_px, "used": self.used, "reason": self.reason}


@dataclass(frozen=True)
class ModelTest:
    """The model test of the module docstring: reduced chi-square of the cells' mean
    residuals against the views' spread within them, its degrees of freedom (2 per cell), and
    the pooled noise of one view's mean residual in a cell [px]."""

    reduced_chi2: float
    dof: int
    cells: int
    view_noise_px: float


@dataclass(frozen=True)
class TangentialTest:
    """Whether the views call for the tangential distortion terms (module docstring): the
    extra-sum-of-squares F statistic of freeing p1 and p2 against holding them at 0, its
    p-value, the principal point's move between the two fits [px], and each other parameter's
    (``fx_px`` ... ``k2``, ``k3`` when fitted: |free - held|, in its unit)."""

    f_statistic: float
    p_value: float
    principal_point_shift_px: float
    model_spread: dict[str, float] = field(default_factory=dict)

    @property
    def fitted(self) -> bool:
        """p1, p2 are fitted: freeing them reduces the residual beyond chance."""
        return self.p_value < TANGENTIAL_P_VALUE

    def reason(self) -> str:
        """Why p1 and p2 are held at 0 (for their verdicts)."""
        return (f"held at 0: fitting p1 and p2 reduces the reprojection residual no more than "
                f"noise does (F = {self.f_statistic:.2f}, p = {self.p_value:.2f}; fitted only "
                f"below p = {TANGENTIAL_P_VALUE:g}), and freeing them would move the principal "
                f"point by {self.principal_point_shift_px:.2f} px")


@dataclass(frozen=True)
class PhotoCalibration:
    """The calibration of a set of images.

    Attributes
    ----------
    result : IntrinsicsResult
        The calibration (:func:`calibration.intrinsics.calibrate_intrinsics`).
    views : list of ViewReport
        Every image, in the order given.
    image_shape : (H, W) [px]
    board : PhotoBoard
    model : ModelTest
    jackknife_std : dict
        Parameter name (``fx_px`` ... ``p2``, ``k3`` when fitted) -> the delete-one-view
        jackknife's standard deviation.
    corner_radius : float
        The largest normalised image radius of the corners used [1].
    fit_k3 : bool
    verdicts : Verdicts
    tangential : TangentialTest or None
        The test that decided whether p1, p2 were fitted (None: not tested, fitted).
    """

    result: IntrinsicsResult
    views: list[ViewReport]
    image_shape: tuple[int, int]
    board: PhotoBoard
    model: ModelTest
    jackknife_std: dict[str, float]
    corner_radius: float
    fit_k3: bool
    verdicts: Verdicts
    tangential: TangentialTest | None = None

    @property
    def fit_tangential(self) -> bool:
        return self.tangential is None or self.tangential.fitted

    @property
    def parameters(self) -> dict[str, float]:
        """fx_px, fy_px, cx_px, cy_px [px] and k1, k2, p1, p2 (k3 when fitted) [1]."""
        k = self.result.intrinsics
        out = {"fx_px": k.fx_px, "fy_px": k.fy_px, "cx_px": k.cx_px, "cy_px": k.cy_px}
        out.update(zip(("k1", "k2", "p1", "p2", "k3"), k.distortion, strict=True))
        if not self.fit_k3:
            out.pop("k3")
        return out


# -- calibration -----------------------------------------------------------------------------
def calibrate_photos(sources: Sequence[str | Path], board: PhotoBoard, *,
                     fit_k3: bool = False) -> PhotoCalibration:
    """Detect, calibrate and judge (module docstring). Images of another size than the first
    are refused (one camera, one image size); too few usable views is an error naming how many
    were usable and how many are needed."""
    paths = image_sources(sources)
    reports: dict[str, ViewReport] = {}
    views: list[BoardView] = []
    shape: tuple[int, int] | None = None
    for i, p in enumerate(paths):
        name = _view_name(p, i, paths)
        grey = load_grey(p)
        if shape is None:
            shape = (int(grey.shape[0]), int(grey.shape[1]))
        if tuple(grey.shape) != shape:
            reports[name] = ViewReport(name, str(p), 0, reason=(
                f"image is {grey.shape[1]} x {grey.shape[0]} px, the first was {shape[1]} x "
                f"{shape[0]}: one camera, one image size"))
            continue
        det = detect_corners(grey, board)
        n = 0 if det is None else len(det.corner_ids)
        if det is None or n < MIN_CORNERS_PER_VIEW:
            why = ("board not found" if det is None else
                   f"{n} corners found, fewer than {MIN_CORNERS_PER_VIEW}")
            if board.kind == "chessboard" and det is None:
                why += (f" (a chessboard must show all its {board.squares_x - 1} x "
                        f"{board.squares_y - 1} inner corners)")
            reports[name] = ViewReport(name, str(p), n, reason=why)
            continue
        reports[name] = ViewReport(name, str(p), n)
        views.append(BoardView(name, 0.0, "photo", det.object_points_m, det.image_points_px,
                               det.corner_ids, shape))
    if len(views) < MIN_VIEWS:
        refused = [r for r in reports.values() if not r.used]
        detail = "; ".join(f"{r.name}: {r.reason}" for r in refused[:5])
        raise InvalidInputError(
            "IMAGES", f"{len(views)} of {len(paths)} images show the board with at least "
            f"{MIN_CORNERS_PER_VIEW} corners; at least {MIN_VIEWS} are needed"
            + (f" ({detail}{' ...' if len(refused) > 5 else ''})" if detail else "")
            + ": check --board, --squares (squares, not inner corners), the board in focus and "
            "whole in view, or add images")
    assert shape is not None
    result = calibrate_intrinsics(views, shape, fix_k3=not fit_k3, guess_from_preset=False,
                                  refuse_degenerate=False)
    for r in result.rejected:
        old = reports[r["name"]]
        reports[r["name"]] = ViewReport(old.name, old.path, old.corners, reason=r["reason"])
    for name, rms in result.per_view_rms_px.items():
        old = reports[name]
        reports[name] = ViewReport(old.name, old.path, old.corners, rms_px=rms)
    used = [v for v in views if v.name in result.per_view_rms_px]
    result, tangential = _tangential_terms(used, result, shape, fit_k3)
    model = model_test(used, result, shape)
    jack = _jackknife(used, result, fit_k3, tangential.fitted)
    radius = _corner_radius(used, result)
    cal = PhotoCalibration(result, [reports[_view_name(p, i, paths)] for i, p in
                                    enumerate(paths)], shape, board, model, jack, radius,
                           fit_k3, Verdicts(), tangential)
    return PhotoCalibration(**{**cal.__dict__, "verdicts": photo_verdicts(cal)})


def _tangential_terms(views: Sequence[BoardView], full: IntrinsicsResult,
                      shape: tuple[int, int], fit_k3: bool,
                      ) -> tuple[IntrinsicsResult, TangentialTest]:
    """The calibration with p1, p2 held at 0 if the views do not call for them (module
    docstring), else ``full``; and the test that decided.

    The extra-sum-of-squares F test of the two nested fits on the same views: ``F = ((RSS_0 -
    RSS_1) / 2) / (RSS_1 / (2 N - q))`` with ``N`` corners and ``q`` parameters of the full fit
    (intrinsics, distortion and 6 per view). A held fit that rejects another view is not
    comparable: the full one stands.
    """
    held = calibrate_intrinsics(list(views), shape, fix_k3=not fit_k3, guess_from_preset=False,
                                refuse_degenerate=False, zero_tangential=True)
    n = full.n_corners
    q = 8 + (1 if fit_k3 else 0) + 6 * len(views)
    dof = 2 * n - q
    rss_full, rss_held = full.rms_px**2 * n, held.rms_px**2 * n
    comparable = held.n_corners == n and dof > 0 and rss_full > 0.0
    f_stat = (max(rss_held - rss_full, 0.0) / 2.0) / (rss_full / dof) if comparable else math.inf
    p_value = float(stats.f.sf(f_stat, 2, dof)) if comparable else 0.0
    a, b = full.intrinsics, held.intrinsics
    spread = {name: abs(x - y) for name, x, y in zip(
        ("fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "p1", "p2", "k3"),
        _param_vector(full, True), _param_vector(held, True), strict=True)
        if name not in ("p1", "p2")}
    test = TangentialTest(f_stat, p_value, math.hypot(a.cx_px - b.cx_px, a.cy_px - b.cy_px),
                          spread)
    return (full if test.fitted else held), test


def _view_name(path: Path, index: int, paths: Sequence[Path]) -> str:
    """The view's name: the file's (or frame folder's) name, with the parent's when names
    repeat."""
    names = [p.name for p in paths]
    if names.count(path.name) == 1:
        return path.name
    return f"{path.parent.name}/{path.name}#{index}"


def _residuals(view: BoardView, result: IntrinsicsResult) -> np.ndarray:
    """Detected minus reprojected corners of ``view`` (n, 2) [px]."""
    k = result.intrinsics
    kmat = np.array([[k.fx_px, 0, k.cx_px], [0, k.fy_px, k.cy_px], [0, 0, 1]], dtype=np.float64)
    rvec, tvec = result.poses[view.name]
    proj, _ = cv2.projectPoints(view.object_points_m.astype(np.float64), rvec, tvec, kmat,
                                np.asarray(k.distortion, dtype=np.float64))
    return view.image_points_px - proj.reshape(-1, 2)


def model_test(views: Sequence[BoardView], result: IntrinsicsResult,
               shape: tuple[int, int], grid: tuple[int, int] = CELL_GRID) -> ModelTest:
    """Whether the residuals depend on where in the image a corner is (module docstring)."""
    h, w = shape
    units: dict[tuple[int, int], list[np.ndarray]] = {}
    for v in views:
        res = _residuals(v, result)
        row = np.clip((v.image_points_px[:, 1] + 0.5) * grid[0] / h, 0, grid[0] - 1).astype(int)
        col = np.clip((v.image_points_px[:, 0] + 0.5) * grid[1] / w, 0, grid[1] - 1).astype(int)
        for cell in set(zip(row.tolist(), col.tolist(), strict=True)):
            inside = (row == cell[0]) & (col == cell[1])
            units.setdefault(cell, []).append(res[inside].mean(axis=0))
    between, within, dof_within, cells = 0.0, 0.0, 0, 0
    for values in units.values():
        u = np.asarray(values)
        if len(u) < MIN_VIEWS_PER_CELL:
            continue
        mean = u.mean(axis=0)
        within += float(np.sum((u - mean) ** 2))
        dof_within += 2 * (len(u) - 1)
        between += len(u) * float(np.sum(mean**2))
        cells += 1
    if cells == 0 or dof_within == 0 or within <= 0.0:
        return ModelTest(math.inf, 0, cells, math.nan)
    s2 = within / dof_within
    return ModelTest(between / (2 * cells) / s2, 2 * cells, cells, math.sqrt(s2))


def _param_vector(result: IntrinsicsResult, fit_k3: bool) -> np.ndarray:
    k = result.intrinsics
    values = [k.fx_px, k.fy_px, k.cx_px, k.cy_px, *k.distortion[:4]]
    return np.asarray(values + ([k.distortion[4]] if fit_k3 else []), dtype=np.float64)


def _jackknife(views: Sequence[BoardView], result: IntrinsicsResult, fit_k3: bool,
               fit_tangential: bool = True) -> dict[str, float]:
    """The delete-one-view jackknife's standard deviation of each parameter fitted
    (:func:`calibration.rig_verdicts.jackknife_std` of :func:`one_step_leave_outs`); inf for
    every parameter when a view's removal leaves them undetermined (a row that is not finite:
    the spread of the others would hide it)."""
    names = ["fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2"] + (
        ["p1", "p2"] if fit_tangential else []) + (["k3"] if fit_k3 else [])
    if len(views) < 3:
        return dict.fromkeys(names, math.inf)
    estimates = one_step_leave_outs(views, result, fit_k3, fit_tangential)
    if not np.all(np.isfinite(estimates)):
        return dict.fromkeys(names, math.inf)
    return dict(zip(names, (float(s) for s in jackknife_std(estimates)), strict=True))


def one_step_leave_outs(views: Sequence[BoardView], result: IntrinsicsResult, fit_k3: bool,
                        fit_tangential: bool) -> np.ndarray:
    """Each view left out in turn: the camera's parameters (fx, fy, cx, cy, k1, k2, then p1, p2
    if fitted, then k3 if fitted), one row per view, by one Gauss-Newton step from the full
    fit (``result``: its intrinsics and board poses, a least-squares optimum of every view).

    At the optimum the gradient of the corners' squared error vanishes, so leaving view ``i``
    out leaves the gradient ``-J_i^T r_i`` of its own residuals ``r_i``; the step solves the
    other views' normal equations with every board pose eliminated (the Schur complement
    ``S - S_i``, ``S_i = A_i - B_i D_i^-1 B_i^T`` the view's share from its camera block
    ``A_i``, cross block ``B_i`` and pose block ``D_i``; the Jacobians are
    :func:`cv2.projectPoints`'). Starting OpenCV's calibration again for every view (what this
    replaces) is not safe: on a set of 167 steeply tilted views, the fits without one view ran
    off to 1.3-1.9 px of residual from either start (the views' homographies or the full fit)
    against the full set's 0.09 px, and called the principal point's error 85-349 px. A view
    whose removal leaves the parameters undetermined (a singular system) gives a row of inf.
    """
    k = result.intrinsics
    kmat = np.array([[k.fx_px, 0, k.cx_px], [0, k.fy_px, k.cy_px], [0, 0, 1]], dtype=np.float64)
    dist = np.asarray(k.distortion, dtype=np.float64)
    # projectPoints' Jacobian columns: rvec 0-2, tvec 3-5, fx fy 6-7, cx cy 8-9, k1 k2 p1 p2 k3
    camera_cols = [6, 7, 8, 9, 10, 11] + ([12, 13] if fit_tangential else []) + (
        [14] if fit_k3 else [])
    theta = np.array([k.fx_px, k.fy_px, k.cx_px, k.cy_px, dist[0], dist[1]]
                     + ([dist[2], dist[3]] if fit_tangential else [])
                     + ([dist[4]] if fit_k3 else []))
    shares, grads = [], []
    total = np.zeros((len(theta), len(theta)))
    for v in views:
        rvec, tvec = result.poses[v.name]
        projected, jac = cv2.projectPoints(v.object_points_m.astype(np.float64), rvec, tvec,
                                           kmat, dist)
        r = projected.reshape(-1) - v.image_points_px.astype(np.float64).reshape(-1)
        jc, jp = jac[:, camera_cols], jac[:, :6]
        a, b, d = jc.T @ jc, jc.T @ jp, jp.T @ jp
        try:
            share = a - b @ np.linalg.solve(d, b.T)
        except np.linalg.LinAlgError:  # a pose the view cannot fix: it tells nothing
            share = np.zeros_like(a)
        shares.append(share)
        grads.append(jc.T @ r)
        total += share
    rows = []
    for share, grad in zip(shares, grads, strict=True):
        try:
            step = np.linalg.solve(total - share, grad)
        except np.linalg.LinAlgError:
            rows.append(np.full(len(theta), np.inf))
            continue
        rows.append(theta + step if np.all(np.isfinite(step)) else np.full(len(theta), np.inf))
    return np.asarray(rows)


def _corner_radius(views: Sequence[BoardView], result: IntrinsicsResult) -> float:
    """The largest normalised radius ``|((u - cx) / fx, (v - cy) / fy)|`` of the corners."""
    k = result.intrinsics
    r = [np.hypot((v.image_points_px[:, 0] - k.cx_px) / k.fx_px,
                  (v.image_points_px[:, 1] - k.cy_px) / k.fy_px).max() for v in views]
    return float(max(r))


# -- verdicts --------------------------------------------------------------------------------
def pixel_scale(focal_px: float) -> float:
    """How much larger in pixels a ToF target's angle is at this focal length: ``max(1, f /
    208.33)`` (module docstring).

    >>> round(pixel_scale(532.8), 3), pixel_scale(100.0)
    (2.557, 1.0)
    """
    return max(1.0, focal_px / REFERENCE_FOCAL_PX)


def photo_limits(cal: PhotoCalibration) -> dict[str, float]:
    """Each parameter's limit on its standard deviation (module docstring) [its unit]."""
    k = cal.result.intrinsics
    out = {"fx_px": FOCAL_REL * k.fx_px, "fy_px": FOCAL_REL * k.fy_px,
           "cx_px": PRINCIPAL_POINT_PX * pixel_scale(k.fx_px),
           "cy_px": PRINCIPAL_POINT_PX * pixel_scale(k.fy_px)}
    for coef in ("k1", "k2", "p1", "p2") + (("k3",) if cal.fit_k3 else ()):
        out[coef] = distortion_limit(coef, k.fx_px, cal.corner_radius) * pixel_scale(k.fx_px)
    return out


def photo_verdicts(cal: PhotoCalibration) -> Verdicts:
    """Every written key's verdict (module docstring)."""
    res = cal.result
    n_used = len(res.per_view_rms_px)
    stage = StageEvidence(
        cal.model.reduced_chi2,
        f"the reprojection residuals by image position ({cal.model.cells} cells, {n_used} views)",
        dof=cal.model.dof)
    verdicts = Verdicts()
    for name, limit in photo_limits(cal).items():
        key = f"camera.{name}" if name.endswith("_px") else f"camera.distortion.{name}"
        unit = " px" if name.endswith("_px") else ""
        if res.normal_spread < MIN_NORMAL_SPREAD:
            verdicts.add(key, Verdict(
                "not determined", None,
                f"the board normals are all nearly parallel to one plane (spread "
                f"{res.normal_spread:.3f}, needs {MIN_NORMAL_SPREAD}): tilt the board both ways "
                "about both of its axes"))
            continue
        if name in ("p1", "p2") and not cal.fit_tangential:
            assert cal.tangential is not None
            verdicts.add(key, Verdict("not determined", None, cal.tangential.reason()))
            continue
        std = max(res.std.get(name, math.inf), cal.jackknife_std.get(name, math.inf))
        if not cal.fit_tangential:  # what holding p1, p2 at 0 may cost, in quadrature
            assert cal.tangential is not None
            std = math.hypot(std, cal.tangential.model_spread.get(name, 0.0))
        verdicts.add(key, stage.judged(std, limit, unit, already_honest=True))
    return verdicts


def model_chi2_limit(model: ModelTest) -> float:
    """The reduced chi-square above which the model test says unexplained."""
    return chi2_limit_for(model.dof)


# -- output ----------------------------------------------------------------------------------
CALIBRATION_FILE = "calibration.yaml"


def procedure_record(cal: PhotoCalibration) -> dict[str, Any]:
    """``provenance.procedures.photo_intrinsics``: the image size, the board, the per-view
    figures, the model test and the limits (plain finite JSON)."""
    h, w = cal.image_shape
    res = cal.result
    return {
        "image_size_px": [w, h],
        "board": cal.board.describe(),
        "views": [v.to_json() for v in cal.views],
        "views_used": len(res.per_view_rms_px), "corners_used": res.n_corners,
        "rms_px": res.rms_px,
        "k3": "fitted" if cal.fit_k3 else "held at 0",
        "p1_p2": ("fitted" if cal.fit_tangential else "held at 0"),
        "tangential_test": None if cal.tangential is None else {
            "f_statistic": _finite(cal.tangential.f_statistic),
            "p_value": cal.tangential.p_value,
            "principal_point_shift_px": cal.tangential.principal_point_shift_px},
        "model_test": {"reduced_chi2": _finite(cal.model.reduced_chi2), "dof": cal.model.dof,
                       "cells": cal.model.cells,
                       "view_noise_px": _finite(cal.model.view_noise_px)},
        "normal_spread": res.normal_spread, "corner_radius": cal.corner_radius,
        "std_opencv": {k: _finite(v) for k, v in res.std.items()},
        "std_jackknife": {k: _finite(v) for k, v in cal.jackknife_std.items()},
        "limits": photo_limits(cal),
    }


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def calibration_data(cal: PhotoCalibration, created_utc: str = "") -> dict[str, Any]:
    """The calibration file's content: the camera keys and the provenance."""
    from sim_core.frame_io import package_version

    p = cal.parameters
    camera: dict[str, Any] = {k: p[k] for k in ("fx_px", "fy_px", "cx_px", "cy_px")}
    camera["distortion"] = {k: p.get(k, 0.0) for k in ("k1", "k2", "p1", "p2", "k3")}
    used = len(cal.result.per_view_rms_px)
    return {"camera": camera,
            "provenance": {"created_utc": created_utc, "rig": "photographs",
                           "software": f"toftwin {package_version()}", "frames_used": used,
                           "procedures": {"photo_intrinsics": procedure_record(cal)}}}


def write_calibration_yaml(path: str | Path, cal: PhotoCalibration,
                           created_utc: str = "") -> Path:
    """``calibration.yaml``, validated as a calibration file
    (:func:`sim_core.twin_file.parse_calibration`), with the photographs' image size in
    ``camera.image_size_px``: the lens is checked against that image, and a twin takes the file
    only for a scene camera of that size (:func:`sim_core.twin_apply.apply_to_spec`)."""
    from sim_core.twin_file import parse_calibration, write_calibration

    data = calibration_data(cal, created_utc)
    h, w = cal.image_shape
    data["camera"] = {"image_size_px": [w, h], **data["camera"]}
    try:
        parsed = parse_calibration(data)
    except InvalidInputError as exc:
        raise InvalidInputError(exc.field, f"the fitted lens is no lens for a {w} x {h} image: "
                                f"{exc.message}") from None
    return write_calibration(path, parsed)


def write_opencv_yaml(path: str | Path, cal: PhotoCalibration) -> Path:
    """OpenCV's FileStorage form (:func:`calibration.camera_forms.write_opencv_camera`:
    ``camera_matrix``, ``distortion_coefficients``, ``image_width``, ``image_height``), with
    what OpenCV's calibration sample adds: ``avg_reprojection_error`` [px],
    ``per_view_reprojection_errors`` (views used, in order) and their names, ``nr_of_frames``,
    ``board_width``/``board_height`` (inner corners), ``square_size`` [m]."""
    return write_opencv_camera(path, cal.result.intrinsics, {
        "board_width": cal.board.squares_x - 1,
        "board_height": cal.board.squares_y - 1,
        "square_size": float(cal.board.square_m),
        "nr_of_frames": len(cal.result.per_view_rms_px),
        "avg_reprojection_error": float(cal.result.rms_px),
        "per_view_reprojection_errors": np.asarray(
            list(cal.result.per_view_rms_px.values()), dtype=np.float64).reshape(-1, 1),
        "view_names": " ".join(cal.result.per_view_rms_px),
    })


def write_outputs(out: str | Path, cal: PhotoCalibration, created_utc: str = "") -> dict[str, Path]:
    """``OUT/calibration.yaml``, ``OUT/verdicts.json`` and ``OUT/opencv_intrinsics.yml``."""
    from calibration.verdicts import VERDICTS_FILE, write_verdicts

    d = Path(out)
    d.mkdir(parents=True, exist_ok=True)
    return {"calibration": write_calibration_yaml(d / CALIBRATION_FILE, cal, created_utc),
            "verdicts": write_verdicts(d / VERDICTS_FILE, cal.verdicts),
            "opencv": write_opencv_yaml(d / OPENCV_FILE, cal)}
