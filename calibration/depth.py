"""The camera's depth errors from the board: phase offset, wiggling and fixed pattern.

For every view the board's pose (intrinsics calibration) predicts each pixel's true range r,
hence its true phase phi = 4 pi f r / c (seed eq. 7); the measured phase of the averaged frames
differs by the camera's errors (:mod:`sim_core.depth_errors`):

    e = wrap(phi_m - phi) = offset + sum_h (alpha_h sin h phi + beta_h cos h phi) + 4 pi f o(px) / c

Fitted by alternating weighted least squares (weights: amplitude squared, the inverse phase
variance): the global terms over all board pixels, then each pixel's offset as its weighted mean
residual (the offsets' weighted mean is pinned to 0: the global offset carries it), a few
rounds, residuals beyond 5 MADs dropped (mixed pixels, multipath). The harmonics 1-6 are fitted
together; over the narrow span of phases a board at ~1 m shows, low harmonics are nearly
collinear, so the solve keeps only the directions the data determine (SVD truncation) and the
result says how many: the model reproduces the errors over the span seen, which is where the
twin uses it; outside that span it is not determined and the result says so.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calibration.board_range import board_range_m
from sim_core.constants import SPEED_OF_LIGHT_M_S
from sim_core.depth_errors import (
    MAX_WIGGLING_SLOPE,
    grid_pixel_offsets_m,
    pixel_offsets_to_grid,
)
from sim_core.errors import InvalidInputError
from sim_core.twin_file import DepthErrors, WigglingTerm

HARMONICS = (1, 2, 3, 4, 5, 6)
ROUNDS = 6
#: singular values below this share of the largest are not determined by the data
RCOND = 1e-3
GRID_STEP_PX = 4
#: pixels dimmer than this share of the view's bright level are not used
MIN_AMPLITUDE_SHARE = 0.15


@dataclass(frozen=True)
class DepthView:
    """One view for the depth fit: measured phases, the true range, the pixels to use."""

    name: str
    phase_rad: np.ndarray  #: (n_f, H, W) measured
    amplitude: np.ndarray  #: (H, W) [DN]
    true_range_m: np.ndarray  #: (H, W)
    mask: np.ndarray  #: (H, W) bool


@dataclass(frozen=True)
class DepthCalibration:
    """Result: the calibration file's ``camera.depth`` plus residuals."""

    depth_errors: DepthErrors
    rms_before_mm: float
    rms_after_mm: float
    per_view_rms_after_mm: dict[str, float]
    phase_span_rad: tuple[float, float]
    range_span_m: tuple[float, float]
    determined_terms: int
    total_terms: int
    coverage: float
    residual_after_mm: np.ndarray = field(repr=False, default=None)
    residual_before_mm: np.ndarray = field(repr=False, default=None)
    #: (H, W) pixels that saw the board in some view (where the fixed pattern is measured)
    pixels_seen: np.ndarray = field(repr=False, default=None)

    def summary(self) -> dict:
        return {"rms_before_mm": self.rms_before_mm, "rms_after_mm": self.rms_after_mm,
                "worst_view_rms_mm": max(self.per_view_rms_after_mm.values()),
                "phase_span_rad": list(self.phase_span_rad),
                "range_span_m": list(self.range_span_m),
                "determined_terms": self.determined_terms, "total_terms": self.total_terms,
                "pixel_coverage": self.coverage,
                "note": "wiggling determined only over range_span_m"}

    def plot(self, ax) -> str:
        bins = np.linspace(-30, 30, 121)
        ax.hist(self.residual_before_mm, bins=bins, alpha=0.6, label="before")
        ax.hist(self.residual_after_mm, bins=bins, alpha=0.6, label="after")
        ax.set_xlabel("range residual on the board [mm]")
        ax.legend()
        return (f"Depth residual on the board: {self.rms_before_mm:.1f} mm RMS before, "
                f"{self.rms_after_mm:.2f} mm after")


def _wrap(x):
    return np.mod(x + np.pi, 2 * np.pi) - np.pi


def fit_depth_errors(views: list[DepthView], frequencies_hz) -> DepthCalibration:
    """Fit the depth errors (module docstring); raises when the views cannot determine them."""
    freqs = np.asarray(frequencies_hz, dtype=np.float64).ravel()
    if not views:
        raise InvalidInputError("depth.views", "no board views to fit the depth errors from")
    shape = views[0].amplitude.shape
    k_rad = 4 * np.pi * freqs / SPEED_OF_LIGHT_M_S  # phase per metre of range
    # Gather samples: pixel index, frequency, true phase, measured residual, weight, view.
    pix, fk, phi, e, w, vid = [], [], [], [], [], []
    for i, v in enumerate(views):
        amp = np.asarray(v.amplitude, dtype=np.float64)
        ok = v.mask & np.isfinite(v.true_range_m) & np.isfinite(amp)
        if ok.any():
            ok &= amp >= MIN_AMPLITUDE_SHARE * np.percentile(amp[ok], 99)
        idx = np.flatnonzero(ok)
        for k in range(freqs.size):
            t = k_rad[k] * v.true_range_m.ravel()[idx]
            m = np.asarray(v.phase_rad[k], dtype=np.float64).ravel()[idx]
            pix.append(idx)
            fk.append(np.full(idx.size, k))
            phi.append(t)
            e.append(_wrap(m - t))
            w.append(amp.ravel()[idx] ** 2)
            vid.append(np.full(idx.size, i))
    pix, fk, phi, e, w, vid = (np.concatenate(a) for a in (pix, fk, phi, e, w, vid))
    if pix.size < 1000:
        raise InvalidInputError("depth.views", f"only {pix.size} board pixels are usable; at "
                                "least 1000 are needed (is the board detected and lit?)")
    n_pix = shape[0] * shape[1]
    keep = np.ones(pix.size, dtype=bool)
    offs = np.zeros(n_pix)
    n_terms = freqs.size + 2 * len(HARMONICS)
    rank = 0
    coef = np.zeros(n_terms)

    def design(sel):
        cols = [(fk[sel] == k).astype(float) for k in range(freqs.size)]
        for h in HARMONICS:
            cols += [np.sin(h * phi[sel]), np.cos(h * phi[sel])]
        return np.stack(cols, axis=1)

    for _ in range(ROUNDS):
        y = e - k_rad[fk] * offs[pix]
        sw = np.sqrt(w[keep])
        a = design(keep) * sw[:, None]
        scale = np.linalg.norm(a, axis=0)
        scale[scale == 0] = 1.0
        sol, _, rank, _ = np.linalg.lstsq(a / scale, y[keep] * sw, rcond=RCOND)
        coef = sol / scale
        glob = design(np.ones(pix.size, dtype=bool)) @ coef
        r_rng = (e - glob) / k_rad[fk]  # residual as a range [m]
        num = np.bincount(pix[keep], weights=(w * r_rng)[keep], minlength=n_pix)
        den = np.bincount(pix[keep], weights=w[keep], minlength=n_pix)
        seen = den > 0
        offs = np.where(seen, num / np.where(seen, den, 1.0), 0.0)
        mean = np.sum(offs[seen] * den[seen]) / np.sum(den[seen])
        offs[seen] -= mean
        resid = (e - glob) / k_rad[fk] - offs[pix]
        mad = np.median(np.abs(resid[keep] - np.median(resid[keep])))
        keep = np.abs(resid) <= max(5 * 1.4826 * mad, 1e-4)
    glob = design(np.ones(pix.size, dtype=bool)) @ coef
    before = e / k_rad[fk] - np.average(e / k_rad[fk], weights=w)
    terms = []
    for j, h in enumerate(HARMONICS):
        al, be = coef[freqs.size + 2 * j], coef[freqs.size + 2 * j + 1]
        amp = float(np.hypot(al, be))
        if amp > 1e-6:
            terms.append(WigglingTerm(harmonic=h, amplitude_rad=min(amp, 0.5),
                                      phase_rad=float(np.arctan2(be, al))))
    slope = sum(t.amplitude_rad * t.harmonic for t in terms)
    if slope >= MAX_WIGGLING_SLOPE:
        raise InvalidInputError(
            "depth.wiggling", f"the fitted wiggling has a slope of {slope:.2f} (limit "
            f"{MAX_WIGGLING_SLOPE}): the phase span seen ({phi.min():.2f}-{phi.max():.2f} rad) "
            "does not determine it; add views at other distances (a flat wall)")
    offs_map = np.where(seen, offs, np.nan).reshape(shape)
    grid = pixel_offsets_to_grid(offs_map, GRID_STEP_PX)
    # The residual the calibration file leaves: with the grid's interpolated offsets.
    stored = grid_pixel_offsets_m(grid, shape).ravel()
    after = (e - glob) / k_rad[fk] - stored[pix]
    spec = DepthErrors(phase_offset_rad=[float(_wrap(c)) for c in coef[: freqs.size]],
                       wiggling=terms, pixel_offset_m=grid)
    per_view = {views[i].name: float(np.sqrt(np.mean(after[(vid == i) & keep] ** 2))) * 1e3
                for i in range(len(views)) if np.any((vid == i) & keep)}
    rng_all = phi / k_rad[fk]
    return DepthCalibration(
        depth_errors=spec,
        rms_before_mm=float(np.sqrt(np.mean(before[keep] ** 2))) * 1e3,
        rms_after_mm=float(np.sqrt(np.mean(after[keep] ** 2))) * 1e3,
        per_view_rms_after_mm=per_view,
        phase_span_rad=(float(phi.min()), float(phi.max())),
        range_span_m=(float(rng_all.min()), float(rng_all.max())),
        determined_terms=int(rank), total_terms=n_terms,
        coverage=float(np.mean(seen)), pixels_seen=seen.reshape(shape),
        residual_after_mm=after[keep] * 1e3, residual_before_mm=before[keep] * 1e3,
    )


def depth_views_from_captures(intr_result, views_caps, board) -> list[DepthView]:
    """DepthViews of the board views that have a pose: true range from the pose, its mask."""
    from sim_core.boards import board_size_m

    out = []
    for view, cap in views_caps:
        pose = intr_result.poses.get(view.name)
        if pose is None:
            continue
        rng, inside = board_range_m(intr_result.intrinsics, pose[0], pose[1],
                                    board_size_m(board))
        out.append(DepthView(view.name, cap.phase_rad, cap.amplitude, rng,
                             inside & cap.valid))
    return out
