"""Calibration boards as scene objects: a ChArUco board and a plain checkerboard.

A board is flat, in its object's local xy plane, facing +z, centred on the object's origin. Its
pattern comes from OpenCV (``cv2.aruco.CharucoBoard.generateImage``) or, for the checkerboard,
from alternating squares; the renderer sees it as exact geometry: one quad per run of equal
cells of the pattern, black runs with the board's black material and white runs with its white
one (two materials of one object, :func:`board_triangles`). Edges are then exact, with no
texel aliasing, and the compiled kernels need no texture lookup.

OpenCV's board frame (what ``matchImagePoints`` and ``getChessboardCorners`` return) has its
origin at the board's top-left corner as drawn, x along ``squares_x``, y along ``squares_y``
(down the drawing) and z into the board; :func:`object_from_board` takes it to the object frame.
"""

from __future__ import annotations

import numpy as np

from sim_core.errors import InvalidInputError

#: cells of the drawn pattern per marker bit when the sizes are not on one grid
_FINE_CELL_M = 0.002
#: largest side of a board's drawn pattern [cells] (its quads grow with it)
MAX_PATTERN_CELLS = 4096


def _cv2():
    import cv2

    return cv2


def aruco_dictionary(name: str):
    """The predefined ArUco dictionary ``name`` (e.g. ``"DICT_4X4_50"``)."""
    cv2 = _cv2()
    code = getattr(cv2.aruco, name, None)
    if not name.startswith("DICT_") or not isinstance(code, int):
        allowed = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_"))
        raise InvalidInputError("dictionary", f"unknown ArUco dictionary {name!r}; allowed: "
                                f"{allowed}")
    return cv2.aruco.getPredefinedDictionary(code)


def dictionary_names() -> list[str]:
    """The names of OpenCV's predefined ArUco dictionaries."""
    cv2 = _cv2()
    return sorted(n for n in dir(cv2.aruco)
                  if n.startswith("DICT_") and isinstance(getattr(cv2.aruco, n), int))


def markers_needed(squares_x: int, squares_y: int) -> int:
    """ArUco markers on a ChArUco board: one in every other square (OpenCV's layout).

    >>> markers_needed(5, 5), markers_needed(40, 40)
    (12, 800)
    """
    return squares_x * squares_y // 2


def board_problem(board) -> str | None:
    """Why a ``charuco_board`` mesh spec cannot be drawn, or None (a checkerboard always can).

    Its dictionary must exist and hold a marker for every other square; the pattern is drawn
    with at most :data:`MAX_PATTERN_CELLS` cells a side, a marker with at least one cell per bit
    and border bit.
    """
    if board.kind != "charuco_board":
        return None
    names = dictionary_names()
    if board.dictionary not in names:
        return f"dictionary: unknown ArUco dictionary {board.dictionary!r}; allowed: {names}"
    dictionary = aruco_dictionary(board.dictionary)
    capacity = int(dictionary.bytesList.shape[0])
    need = markers_needed(board.squares_x, board.squares_y)
    if need > capacity:
        return (f"squares_x, squares_y: a {board.squares_x} x {board.squares_y} board needs "
                f"{need} markers; {board.dictionary} holds {capacity}: use at most "
                f"{2 * capacity + 1} squares in all, or a dictionary with more markers (e.g. "
                "DICT_4X4_1000)")
    cell, per_square, marker_cells = _pattern_grid(board, dictionary)
    w, h = board.squares_x * per_square, board.squares_y * per_square
    if max(w, h) > MAX_PATTERN_CELLS:
        return (f"square_m: the pattern is drawn at {cell * 1e3:.3g} mm cells, {w} x {h} of them; "
                f"allowed: at most {MAX_PATTERN_CELLS} a side (smaller squares, or a marker_m that "
                "divides the square into whole cells)")
    bits = dictionary.markerSize + 2
    if marker_cells < bits:
        return (f"marker_m: {board.marker_m:g} m is drawn with {marker_cells} cells of "
                f"{cell * 1e3:.3g} mm, fewer than the {bits} bits of a {board.dictionary} marker "
                f"and its border; allowed: at least {(bits + 0.5) * cell:.3g} m")
    return None


def _pattern_grid(board, dictionary) -> tuple[float, int, int]:
    """How a ChArUco board's pattern is drawn: the cell size [m], cells per square, and cells
    per marker side.

    One cell per marker bit when the square and its margin are whole numbers of them (the
    drawing is exact); else cells of about :data:`_FINE_CELL_M`, a whole number per square, and
    the marker rounded to whole cells (OpenCV's drawing fails on sizes that are not, issue 25).
    """
    cell = board.marker_m / (dictionary.markerSize + 2)
    per_square = board.square_m / cell
    margin = (board.square_m - board.marker_m) / 2.0 / cell
    if abs(per_square - round(per_square)) > 1e-6 or abs(margin - round(margin)) > 1e-6:
        per_square = max(1, round(board.square_m / _FINE_CELL_M))
        cell = board.square_m / per_square
        margin = (board.square_m - board.marker_m) / 2.0 / cell
    n, m = round(per_square), max(1, round(margin))  # a marker smaller than its square
    return cell, n, n - 2 * m


def cv2_board(board):
    """The OpenCV ``CharucoBoard`` of a ``charuco_board`` mesh spec (None for a checkerboard)."""
    if board.kind != "charuco_board":
        return None
    cv2 = _cv2()
    return cv2.aruco.CharucoBoard((board.squares_x, board.squares_y), board.square_m,
                                  board.marker_m, aruco_dictionary(board.dictionary))


def board_size_m(board) -> tuple[float, float]:
    """Width (along squares_x) and height of the pattern [m] (margins excluded)."""
    return board.squares_x * board.square_m, board.squares_y * board.square_m


def pattern_cells(board) -> tuple[np.ndarray, float]:
    """The pattern as a boolean image (True = white), row 0 at the top, and its cell size [m]."""
    if board.kind == "checkerboard":
        r, c = np.mgrid[0 : board.squares_y, 0 : board.squares_x]
        return ((r + c) % 2) == 1, board.square_m
    dictionary = aruco_dictionary(board.dictionary)
    cell, per_square, marker_cells = _pattern_grid(board, dictionary)
    # Drawn in cell units, so that OpenCV's squares and markers are whole pixels.
    drawing = _cv2().aruco.CharucoBoard((board.squares_x, board.squares_y), float(per_square),
                                        float(marker_cells), dictionary)
    img = drawing.generateImage((board.squares_x * per_square, board.squares_y * per_square),
                                marginSize=0, borderBits=1)
    return img > 127, cell


def _runs(row: np.ndarray):
    """(start, stop, value) of the runs of equal values in a 1-D array."""
    edges = np.flatnonzero(np.diff(row.astype(np.int8))) + 1
    starts = np.concatenate([[0], edges])
    stops = np.concatenate([edges, [row.size]])
    return [(int(a), int(b), bool(row[a])) for a, b in zip(starts, stops, strict=True)]


def board_triangles(board) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (n, 3, 3) of the board in its object frame, and per triangle 0 = black, 1 = white.

    Quads of row runs of equal cells, counter-clockwise seen from +z (normals +z); a white
    ``margin_m`` frames the pattern.
    """
    cells, size = pattern_cells(board)
    h, w = cells.shape
    width, height = w * size, h * size
    quads, colours = [], []
    for i in range(h):
        y1 = height / 2.0 - i * size  # top edge of the row (row 0 at the top)
        y0 = y1 - size
        for a, b, white in _runs(cells[i]):
            quads.append((-width / 2.0 + a * size, -width / 2.0 + b * size, y0, y1))
            colours.append(white)
    m = board.margin_m
    if m > 0.0:
        W, H = width / 2.0, height / 2.0
        for q in ((-W - m, W + m, H, H + m), (-W - m, W + m, -H - m, -H),
                  (-W - m, -W, -H, H), (W, W + m, -H, H)):
            quads.append(q)
            colours.append(True)
    tris, tri_white = [], []
    for (x0, x1, y0, y1), white in zip(quads, colours, strict=True):
        a, b, c, d = (x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)
        tris += [(a, b, c), (a, c, d)]
        tri_white += [white, white]
    return np.asarray(tris, dtype=np.float64), np.asarray(tri_white, dtype=np.int32)


def object_from_board(board) -> np.ndarray:
    """4x4 rigid transform from OpenCV's board frame to the board object's local frame.

    A board point (bx, by, bz) is at (bx - W/2, H/2 - by, -bz) in the object frame: a half
    turn about x, then the pattern's centre to the origin.
    """
    width, height = board_size_m(board)
    m = np.diag([1.0, -1.0, -1.0, 1.0])
    m[:3, 3] = (-width / 2.0, height / 2.0, 0.0)
    return m


def board_corners_m(board) -> tuple[np.ndarray, np.ndarray]:
    """The corners a detector reports, in OpenCV's board frame: (n, 3) points and their ids.

    ChArUco: the inner chessboard corners with OpenCV's ids; checkerboard: the inner corners
    row by row (the order ``findChessboardCornersSB`` reports them in).
    """
    if board.kind == "charuco_board":
        pts = np.asarray(cv2_board(board).getChessboardCorners(), dtype=np.float64)
        return pts, np.arange(len(pts))
    j, i = np.mgrid[1 : board.squares_y, 1 : board.squares_x]
    pts = np.stack([i.ravel() * board.square_m, j.ravel() * board.square_m,
                    np.zeros(i.size)], axis=1)
    return pts, np.arange(len(pts))
