"""Finding a calibration board's corners in an amplitude image (OpenCV).

At this camera's resolution a 80 mm square covers about 17 pixels at 1 m, too few for the ArUco
detector to read the markers reliably (CALIBRATION-NOTES.md); upscaling the image (cubic) before
detection, then mapping the corners back, finds nearly all of them. The amplitude (DN, any scale)
is stretched to 8 bits between robust percentiles. ChArUco boards use OpenCV's
``CharucoDetector``; checkerboards ``findChessboardCornersSB``. The corners are refined to
sub-pixel accuracy in the upscaled image.

Coordinates: OpenCV's pixel-centre convention (pixel centres at integers); a point ``x_up`` of
the image upscaled by ``s`` is ``(x_up + 0.5) / s - 0.5`` in the original image.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from sim_core.boards import board_corners_m, cv2_board

#: fewest corners a view must show to be used
MIN_CORNERS = 6
#: window of the flat-field levels [px]: more than a square at 1 m (about 20 px)
FLAT_FIELD_PX = 31
#: half size of the saddle-point window [px] (3 x 3)
SADDLE_HALF_PX = 1


@dataclass(frozen=True)
class BoardDetection:
    """Corners found in one image.

    Attributes
    ----------
    object_points_m : (n, 3) float64
        The corners in OpenCV's board frame [m].
    image_points_px : (n, 2) float64
        Where they are in the image [px].
    corner_ids : (n,) int
    image_shape : (H, W)
    """

    object_points_m: np.ndarray = field(repr=False)
    image_points_px: np.ndarray = field(repr=False)
    corner_ids: np.ndarray
    image_shape: tuple[int, int]


def to_8bit(amplitude: np.ndarray) -> np.ndarray:
    """Amplitude stretched to 0-255 between its 1st and 99.5th percentiles (NaN as black)."""
    a = np.nan_to_num(np.asarray(amplitude, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    lo, hi = np.percentile(a, [1.0, 99.5])
    if not hi > lo:
        return np.zeros(a.shape, dtype=np.uint8)
    return np.clip((a - lo) / (hi - lo) * 255.0, 0, 255).astype(np.uint8)


def detect_board(amplitude: np.ndarray, board, upscale: int = 3,
                 min_corners: int = MIN_CORNERS) -> BoardDetection | None:
    """The board's corners in ``amplitude`` (H, W), or None if fewer than ``min_corners``.

    Checkerboards go to :func:`detect_checkerboard`.
    """
    if board.kind != "charuco_board":
        return detect_checkerboard(amplitude, board, upscale, min_corners)
    img = to_8bit(amplitude)
    s = int(upscale)
    big = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC) if s > 1 else img
    pts_all, _ = board_corners_m(board)
    params = cv2.aruco.CharucoParameters()
    det_params = cv2.aruco.DetectorParameters()
    det_params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    detector = cv2.aruco.CharucoDetector(cv2_board(board), params, det_params)
    corners, ids, _, _ = detector.detectBoard(big)
    if ids is None or len(ids) < min_corners:
        return None
    ids = ids.ravel().astype(int)
    corners = corners.reshape(-1, 2).astype(np.float32)
    return _refined(amplitude, big, s, corners, ids, pts_all, min_corners)


def detect_checkerboard(amplitude: np.ndarray, board, upscale: int = 3,
                        min_corners: int = MIN_CORNERS) -> BoardDetection | None:
    """A plain checkerboard's inner corners in ``amplitude`` (H, W), or None.

    OpenCV's ``findChessboardCornersSB`` on the upscaled 8-bit amplitude (the ChArUco path's
    preparation), and if that fails on the upscaled flat-fielded image with
    ``CALIB_CB_NORMALIZE_IMAGE | CALIB_CB_EXHAUSTIVE``. The whole pattern must be in view (the
    detector finds all inner corners or none). OpenCV's order may start at either end of the
    board (on rendered boards at 1 m it reported them reversed in every view): the order is
    fixed so that the cell bounded by the first two rows and columns of corners is black, as
    in :func:`sim_core.boards.pattern_cells` (row 1, column 1). A board whose squares_x +
    squares_y is even looks the same turned by 180 deg; its order is taken with the first
    corner above the last in the image (the board stands upright). Corners are then refined
    as the ChArUco corners are.
    """
    img = to_8bit(amplitude)
    s = int(upscale)
    nx, ny = board.squares_x - 1, board.squares_y - 1
    flat = flat_field(np.asarray(amplitude, dtype=np.float64))
    corners = None
    for prep, flags in ((img, cv2.CALIB_CB_ACCURACY),
                        (np.clip(flat * 255.0, 0, 255).astype(np.uint8),
                         cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE
                         | cv2.CALIB_CB_EXHAUSTIVE)):
        big = cv2.resize(prep, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC) if s > 1 \
            else prep
        ok, found = cv2.findChessboardCornersSB(big, (nx, ny), flags=flags)
        if ok and found is not None and len(found) == nx * ny:
            corners = found.reshape(-1, 2).astype(np.float32)
            break
    if corners is None:
        return None
    xy = (corners.astype(np.float64) + 0.5) / s - 0.5
    if _first_cell_is_white(flat, xy.reshape(ny, nx, 2), (board.squares_x + board.squares_y)):
        corners = corners[::-1].copy()
    pts_all, ids = board_corners_m(board)
    big = cv2.resize(img, None, fx=s, fy=s, interpolation=cv2.INTER_CUBIC) if s > 1 else img
    return _refined(amplitude, big, s, corners, ids, pts_all, min_corners)


def _first_cell_is_white(flat: np.ndarray, grid: np.ndarray, squares_sum: int) -> bool:
    """Whether the detected order must be reversed (see :func:`detect_checkerboard`)."""
    if squares_sum % 2:
        def centre_level(r, c):
            x, y = grid[r : r + 2, c : c + 2].reshape(-1, 2).mean(axis=0)
            return float(cv2.getRectSubPix(flat.astype(np.float32), (1, 1),
                                           (float(x), float(y)))[0, 0])
        # The first cell against its neighbour (colours alternate): robust to shading.
        nb = (0, 1) if grid.shape[1] > 2 else (1, 0)
        return centre_level(0, 0) > centre_level(*nb)
    return bool(grid[0, 0, 1] > grid[-1, -1, 1])


def _refined(amplitude: np.ndarray, big: np.ndarray, s: int, corners: np.ndarray,
             ids: np.ndarray, pts_all: np.ndarray, min_corners: int) -> BoardDetection | None:
    """Sub-pixel corners of the upscaled image, back to the image, saddle-refined."""
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    win = max(2, s * 2)
    refined = cv2.cornerSubPix(big, corners.reshape(-1, 1, 2).copy(), (win, win), (-1, -1), crit)
    xy = (refined.reshape(-1, 2).astype(np.float64) + 0.5) / s - 0.5
    xy, ok = refine_saddle(flat_field(np.asarray(amplitude, dtype=np.float64)), xy)
    if np.count_nonzero(ok) < min_corners:
        return None
    return BoardDetection(pts_all[ids][ok], xy[ok], ids[ok], tuple(amplitude.shape))


def flat_field(image: np.ndarray, size_px: int = FLAT_FIELD_PX) -> np.ndarray:
    """The image with its smooth shading divided out: (a - black) / (white - black).

    The camera's source falls off towards the image's edges and with the board's angle; an
    X-corner blurred by the optics inside such a gradient appears shifted towards the brighter
    side. The white and black levels are the local maximum and minimum over ``size_px`` (more
    than a square), smoothed; the ratio leaves the pattern with uniform contrast.
    """
    a = np.nan_to_num(image, nan=0.0, posinf=0.0, neginf=0.0)
    black, span = flat_field_levels(a, size_px)
    return np.where(span > 0, (a - black) / np.where(span > 0, span, 1.0), 0.0)


def flat_field_levels(image: np.ndarray, size_px: int = FLAT_FIELD_PX
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The black level and the white-minus-black span :func:`flat_field` divides by, (H, W)
    each: a pixel's noise in the flat-fielded image is its noise over the span."""
    from scipy import ndimage

    a = np.nan_to_num(image, nan=0.0, posinf=0.0, neginf=0.0)
    white = ndimage.gaussian_filter(ndimage.maximum_filter(a, size=size_px), size_px / 4.0)
    black = ndimage.gaussian_filter(ndimage.minimum_filter(a, size=size_px), size_px / 4.0)
    return black, white - black


def _saddle_design(half: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The offsets (yy, xx) of a (2 half + 1)^2 patch and the pseudo-inverse of the quadratic's
    design matrix (columns x^2, xy, y^2, x, y, 1)."""
    yy, xx = np.mgrid[-half : half + 1, -half : half + 1].astype(np.float64)
    a = np.stack([xx.ravel() ** 2, xx.ravel() * yy.ravel(), yy.ravel() ** 2, xx.ravel(),
                  yy.ravel(), np.ones(xx.size)], axis=1)
    return yy, xx, np.linalg.pinv(a)


def refine_saddle(image: np.ndarray, points: np.ndarray, half: int = SADDLE_HALF_PX,
                  iterations: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Refine X-corners to the saddle point of a quadratic fitted to the original image.

    Around each point a (2 half + 1)^2 patch is resampled (bilinear) and fitted by least squares
    with f = a x^2 + b xy + c y^2 + d x + e y + g; the corner moves to where its gradient
    vanishes, until the step is below 1e-4 px. A 3 x 3 window stays clear of the ChArUco
    markers' bits next to a corner, which bias ``cornerSubPix``'s gradient window at this
    resolution (measured: 0.10 px RMS against 0.20 px on rendered boards at 1 m). Points whose
    fit is not a saddle (Hessian determinant >= 0), steps away, or touch the border are
    flagged False.
    """
    img = np.nan_to_num(image, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32)
    yy, xx, pinv = _saddle_design(half)
    out = np.asarray(points, dtype=np.float64).copy()
    ok = np.ones(len(out), dtype=bool)
    h, w = img.shape
    for i, (x0, y0) in enumerate(out):
        x, y = x0, y0
        for _ in range(iterations):
            if not (half + 1 <= x < w - half - 1 and half + 1 <= y < h - half - 1):
                ok[i] = False
                break
            patch = cv2.remap(img, (x + xx).astype(np.float32), (y + yy).astype(np.float32),
                              cv2.INTER_LINEAR)
            qa, qb, qc, qd, qe, _ = pinv @ patch.ravel().astype(np.float64)
            det = 4.0 * qa * qc - qb * qb
            if not det < 0.0:
                ok[i] = False
                break
            dx = (-2.0 * qc * qd + qb * qe) / det
            dy = (qb * qd - 2.0 * qa * qe) / det
            if abs(dx) > 1.0 or abs(dy) > 1.0:
                ok[i] = False
                break
            x, y = x + dx, y + dy
            if abs(dx) < 1e-4 and abs(dy) < 1e-4:
                break
        if abs(x - x0) > 1.5 or abs(y - y0) > 1.5:
            ok[i] = False
        out[i] = (x, y)
    return out, ok


def saddle_std_px(image: np.ndarray, points: np.ndarray, pixel_std: np.ndarray,
                  half: int = SADDLE_HALF_PX) -> np.ndarray:
    """The standard deviation of :func:`refine_saddle`'s corners from the image's noise [px].

    At the saddle the gradient ``(d, e)`` of the fitted quadratic vanishes: a perturbation of
    the patch moves the corner by ``-H^-1 (dd, de)`` with ``H = [[2a, b], [b, 2c]]``, and the
    least-squares coefficients carry ``pixel_std^2 pinv pinv^T`` of independent pixel noise
    (bilinear resampling averages neighbours, so this is an upper bound). Returns (n, 2): the
    standard deviation of x and y for each point; inf where the patch is no saddle
    (``det H >= 0``), where the standard deviation reaches beyond the patch (the corner is not
    defined by the image), or where the patch leaves the image.

    Parameters
    ----------
    image : (H, W) float
        The image the corners were refined on (:func:`flat_field` of the amplitude).
    points : (n, 2) float
        The corners [px].
    pixel_std : (H, W) float
        Each pixel's noise in ``image`` (the amplitude's over the flat field's span).
    """
    img = np.nan_to_num(image, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32)
    sd = np.asarray(pixel_std, dtype=np.float64)
    sd = np.where(np.isfinite(sd), sd, np.inf).astype(np.float32)  # NaN: noise unknown, unbounded
    yy, xx, pinv = _saddle_design(half)
    grad = pinv[3:5]  # rows giving (d, e)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    out = np.full(pts.shape, np.inf)
    h, w = img.shape
    for i, (x, y) in enumerate(pts):
        if not (half + 1 <= x < w - half - 1 and half + 1 <= y < h - half - 1):
            continue
        mx, my = (x + xx).astype(np.float32), (y + yy).astype(np.float32)
        patch = cv2.remap(img, mx, my, cv2.INTER_LINEAR).ravel().astype(np.float64)
        sigma = float(np.max(cv2.remap(sd, mx, my, cv2.INTER_LINEAR)))
        qa, qb, qc = (pinv[:3] @ patch)
        det = 4.0 * qa * qc - qb * qb
        if not (det < 0.0 and np.isfinite(sigma)):  # no saddle: the corner is not defined
            continue
        h_inv = np.array([[2.0 * qc, -qb], [-qb, 2.0 * qa]]) / det
        cov = sigma**2 * (h_inv @ grad @ grad.T @ h_inv.T)
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        # beyond the patch the image does not place the corner at all (a flat patch's
        # vanishing curvature): unbounded, not a number of pixels
        if np.all(std <= half + 1):
            out[i] = std
    return out
