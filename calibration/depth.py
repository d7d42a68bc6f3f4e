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
#: the phases (and ranges) a fitted model is claimed over, and judged over: the central 98 % of
#: the board's samples kept by the fit. The last percent at either end is too few samples to
#: pin the wiggling's harmonics there: on reality 201 the model was 2.3 mm off over the last
#: 0.1 rad of the full span (its standard deviation there said 0.4 mm), 0.1-0.4 mm elsewhere
SPAN_QUANTILES = (0.01, 0.99)
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
    #: (n_f, H, W) the measured phases' standard deviation from the noise model, if known
    phase_std_rad: np.ndarray | None = None


@dataclass(frozen=True)
class DepthCalibration:
    """Result: the calibration file's ``camera.depth`` plus residuals."""

    depth_errors: DepthErrors
    rms_before_mm: float
    rms_after_mm: float
    per_view_rms_after_mm: dict[str, float]
    #: the phases and ranges the model is claimed over: the central 98 % of the samples kept
    #: (:data:`SPAN_QUANTILES`)
    phase_span_rad: tuple[float, float]
    range_span_m: tuple[float, float]
    determined_terms: int
    total_terms: int
    coverage: float
    residual_after_mm: np.ndarray = field(repr=False, default=None)
    residual_before_mm: np.ndarray = field(repr=False, default=None)
    #: (H, W) pixels that saw the board in some view (where the fixed pattern is measured)
    pixels_seen: np.ndarray = field(repr=False, default=None)
    #: the residual after against the views' phase noise (:attr:`DepthView.phase_std_rad`):
    #: chi-square per degree of freedom, overall and per view (NaN without the noise)
    reduced_chi2: float = float("nan")
    per_view_reduced_chi2: dict[str, float] = field(default_factory=dict)
    #: per frequency, the largest standard deviation of the global model (offset and wiggling
    #: together) over the phases seen [rad], from the noise (NaN without it)
    model_std_rad: tuple[float, ...] = ()
    #: the RMS over the grid cells seen of a cell's offset's standard deviation [m] (the
    #: target is an RMS over the pixels seen)
    pixel_offset_std_m: float = float("nan")

    def summary(self) -> dict:
        return {"rms_before_mm": self.rms_before_mm, "rms_after_mm": self.rms_after_mm,
                "worst_view_rms_mm": max(self.per_view_rms_after_mm.values()),
                "phase_span_rad": list(self.phase_span_rad),
                "range_span_m": list(self.range_span_m),
                "determined_terms": self.determined_terms, "total_terms": self.total_terms,
                "pixel_coverage": self.coverage, "reduced_chi2": self.reduced_chi2,
                "model_std_rad": list(self.model_std_rad),
                "pixel_offset_std_m": self.pixel_offset_std_m,
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
    pix, fk, phi, e, w, vid, sd = [], [], [], [], [], [], []
    with_noise = all(v.phase_std_rad is not None for v in views)
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
            sd.append(np.asarray(v.phase_std_rad[k], dtype=np.float64).ravel()[idx]
                      if with_noise else np.full(idx.size, np.nan))
    pix, fk, phi, e, w, vid, sd = (np.concatenate(a) for a in (pix, fk, phi, e, w, vid, sd))
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
    phase_span = tuple(float(q) for q in np.quantile(phi[keep], SPAN_QUANTILES))
    range_span = tuple(float(q) for q in np.quantile(rng_all[keep], SPAN_QUANTILES))
    noise = _noise_evidence(views, design, keep, seen, pix, fk, phi, vid, sd, k_rad,
                            after, int(rank), phase_span) if with_noise else {}
    return DepthCalibration(**noise,
        depth_errors=spec,
        rms_before_mm=float(np.sqrt(np.mean(before[keep] ** 2))) * 1e3,
        rms_after_mm=float(np.sqrt(np.mean(after[keep] ** 2))) * 1e3,
        per_view_rms_after_mm=per_view,
        phase_span_rad=phase_span, range_span_m=range_span,
        determined_terms=int(rank), total_terms=n_terms,
        coverage=float(np.mean(seen)), pixels_seen=seen.reshape(shape),
        residual_after_mm=after[keep] * 1e3, residual_before_mm=before[keep] * 1e3,
    )


def _noise_evidence(views, design, keep, seen, pix, fk, phi, vid, sd, k_rad, after,
                    rank: int, phase_span: tuple[float, float]) -> dict:
    """The fit against the phase noise (:class:`DepthCalibration`'s ``reduced_chi2``,
    ``per_view_reduced_chi2``, ``model_std_rad``, ``pixel_offset_std_m``)."""
    # A pixel whose noise is not finite or not positive carries no information (weight 0).
    ok = keep & np.isfinite(sd) & (sd > 0)
    z2 = np.where(ok, (after * k_rad[fk] / np.where(ok, sd, 1.0)) ** 2, 0.0)
    # The file keeps the offsets on a grid (GRID_STEP_PX): each grid cell seen is one
    # parameter (the residual is taken with the grid's offsets), the global model `rank`.
    width = views[0].amplitude.shape[1]
    cell = (pix // width) // GRID_STEP_PX * (width // GRID_STEP_PX + 1) + (pix % width) \
        // GRID_STEP_PX
    dof = int(ok.sum()) - np.unique(cell[ok]).size - rank
    chi2 = float(z2.sum() / dof) if dof > 0 else float("inf")
    per_view = {}
    for i, v in enumerate(views):
        sel = ok & (vid == i)
        if sel.any():
            per_view[v.name] = float(z2[sel].mean())
    # The global model's covariance: whitened design, the same truncation as the fit.
    a = design(ok) / sd[ok][:, None]
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0  # a column without data: its direction is truncated below
    _, sv, vt = np.linalg.svd(a / scale, full_matrices=False)
    det = sv > RCOND * sv[0] if sv.size and sv[0] > 0 else np.zeros(sv.shape, dtype=bool)
    cov = ((vt[det].T / sv[det] ** 2) @ vt[det]) / np.outer(scale, scale)
    grid = np.linspace(*phase_span, 64)  # the span the model is claimed over
    harmonics = [f(h * grid) for h in HARMONICS for f in (np.sin, np.cos)]
    model_std = []
    for k in range(k_rad.size):
        offset = np.zeros((grid.size, k_rad.size))
        offset[:, k] = 1.0
        g = np.column_stack([offset, *harmonics])
        model_std.append(float(np.sqrt(np.max(np.einsum("ij,jk,ik->i", g, cov, g)))))
    # A grid cell's offset is its samples' weighted mean range residual.
    info = np.bincount(cell[ok], weights=(k_rad[fk[ok]] / sd[ok]) ** 2)
    pix_var = 1.0 / info[info > 0] if np.any(info > 0) else np.array([np.inf])
    return {"reduced_chi2": chi2, "per_view_reduced_chi2": per_view,
            "model_std_rad": tuple(model_std),
            "pixel_offset_std_m": float(np.sqrt(np.mean(pix_var)))}


def depth_views_from_captures(intr_result, views_caps, board, noise=None,
                              temperature=None) -> list[DepthView]:
    """DepthViews of the board views that have a pose: true range from the pose, its mask;
    with ``noise`` (a :class:`calibration.noise_gain.NoiseCalibration`) each phase's standard
    deviation from the noise model over the frames averaged; with ``temperature`` (the
    calibrated ``camera.temperature``) the warm-up drift removed from each capture's phases at
    its reported temperature (:func:`calibration.captures.drift_free_phase_rad`), so the depth
    errors fitted are the ones at the start temperature, as the twin applies them."""
    from calibration.captures import drift_free_phase_rad
    from sim_core.boards import board_size_m

    out = []
    for view, cap in views_caps:
        pose = intr_result.poses.get(view.name)
        if pose is None:
            continue
        rng, inside = board_range_m(intr_result.intrinsics, pose[0], pose[1],
                                    board_size_m(board))
        out.append(DepthView(view.name, drift_free_phase_rad(cap, temperature), cap.amplitude, rng,
                             inside & cap.valid, phase_std_rad(cap, noise)))
    return out


def phase_std_rad(cap, noise) -> np.ndarray | None:
    """(n_f, H, W) standard deviation of an averaged capture's phases from the noise model
    (:func:`calibration.noise_gain.tap_difference_variance_dn2`: var(phi) = var(C) / (2 a^2)
    per frame, over the frames averaged); inf where the amplitude is 0 (no phase); None
    without ``noise``."""
    if noise is None:
        return None
    from calibration.noise_gain import tap_difference_variance_dn2

    var_c = tap_difference_variance_dn2(cap.intensity, noise.adc_gain_e_per_dn,
                                        noise.read_noise_e) / max(cap.n_frames, 1)
    c = np.asarray(cap.phase_images, dtype=np.float64)  # (n_f, 4, H, W)
    amp = 0.5 * np.abs((c[:, 0] - c[:, 2]) - 1j * (c[:, 3] - c[:, 1]))  # seed eq. 5, per f
    # a zero amplitude has no phase: its standard deviation is unbounded, not a division error
    return np.where(amp > 0, np.sqrt(var_c / 2.0) / np.where(amp > 0, amp, 1.0), np.inf)
