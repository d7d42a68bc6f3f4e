"""Mount pose and reflectance scales together: maximum likelihood on the measured phasors.

The simulated lab is the twin's own physics with other parameters, and a real camera is what the
twin models; so the measured views are compared with the twin's predictions
(:mod:`calibration.object_twin.render_model`: the same optics, depth errors and sensor, so mixed
pixels, blur and the camera's range errors are in both) in the camera's own measurement: the
averaged raw phasor of every frequency, real and imaginary parts, of every pixel in and around
the mounted objects,

    r = (z_measured - z_predicted(pose, scales)) / sigma,
    sigma^2 = var_sensor / n_frames + var_mc (1 / spp + 1 / MODEL_SPP)

(:func:`phasor_sigma`): ``var_sensor`` the shot and read noise (and quantisation) of one frame's
phasor part from the sensor model at the predicted taps, ``var_mc`` the render's per-sample
Monte Carlo variance, counted for the twin's render and once more for a render of
:data:`MODEL_SPP` samples (the allowance for model error: a simulated lab renders its frames
with the same Monte Carlo, and on glints and silhouettes that noise dominates). A glint or a
silhouette is then weighted by how well it can be predicted, not masked. Pixels the camera
flagged (saturated, SBI) or the twin saturates are left out.

The residual is minimised over the offset (3 translations [mm], 3 extrinsic xyz angles [deg],
the reality's convention, but the translation taken at the mounted objects' centroid instead of
the axis point on the turntable: about the axis point a tilt and a translation move the object
almost alike, a long valley in which the steps crawl) and the determined objects' scales,
plain squares (the maximum likelihood for Gaussian noise), by Levenberg-Marquardt with a
stretch along each accepted step (a render per trial point). Candidates stay within
:data:`REACH` of the pose at which the re-rendered regions were made; a solve that reaches that
edge has its regions made again there and goes on. The Jacobian is by forward differences of
renders with a fixed seed (common random numbers: the residual is a smooth function of the
parameters up to the silhouettes' sample coverage, which the stratified pixel jitter keeps
fine). The weights are fixed during a solve and made again at its result for the next. A last
solve, and the uncertainties, take the pose's columns by central differences
:data:`WIDE_POSE_STEPS` times as wide (0.1 deg, 1 mm): over a forward difference of 0.025 deg
the silhouettes' sample coverage moves in steps, and that noise adds to ``J^T J`` as if it were
information (measured on a random reality's three views: the rotations' ``J^T J`` 2-5 times the
chi-square's own curvature over +-0.1 deg, the fit stopped where the truth had the lower
chi-square, its rotation 5 standard deviations off).

Uncertainties: ``(J^T J)^-1`` of the whitened Jacobian times the reduced chi-square. A parameter
whose standard deviation exceeds its limit (:data:`UNDETERMINED_STD`) is reported as not
determined.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from calibration.captures import AveragedCapture
from calibration.object_twin.render_model import PredictedView, TwinRenderer, measured_phasor
from calibration.verdicts import jackknife_covariance_of
from sim_core.errors import InvalidInputError
from sim_core.geometry import rotation_matrix_xyz_deg
from sim_core.raw import ValidityThresholds
from sim_core.scene_spec import ObjectPose
from sim_core.sensor import SensorParams
from sim_core.twin_file import MountParameters, ObjectParameters, ObjectTwinParameters

#: samples per pixel of the model-error allowance's render (module docstring)
MODEL_SPP = 32
#: forward-difference steps: translations [mm], rotations [deg], scales [1]
STEP_MM, STEP_DEG, STEP_SCALE = 0.25, 0.025, 0.02
#: the solves, each with weights made at its start: (model error relative to the predicted
#: phasor's magnitude [1], most iterations). The first smooths the objective (a
#: glint's edges and brightness are steep functions of the pose: with their full weight the
#: steps from a start a few millimetres off are short), the others are the maximum likelihood.
SOLVES = ((0.05, 12), (0.0, 8), (0.0, 2))
#: a solve stops when a step moves no parameter by more than this share of its difference step
CONVERGED = 0.1
#: the pose's central differences of the last solve and the uncertainties, in difference steps
#: (0.1 deg, 1 mm: module docstring)
WIDE_POSE_STEPS = 4.0
#: most iterations of the last solve, with those differences
WIDE_ITERATIONS = 3
#: the coarse search of the start along the turntable's axis: half-width and step [mm]
HEIGHT_SEARCH_MM = (8.0, 2.0)
#: largest stretch of an accepted step, in multiples of it
MAX_STRETCH = 8.0
#: Levenberg-Marquardt's damping: the least, its factor up after a failed trial (down by its
#: square after a success), and the most before a solve gives up
DAMPING = (1e-4, 4.0, 1e4)
#: largest change of a translation [mm], a rotation [deg], a scale [1] in one iteration
MAX_STEP = (5.0, 1.0, 0.5)
#: farthest a candidate's translation [mm] and angles [deg] go, per axis, from the pose at which
#: the regions were rendered (a silhouette then stays inside its region's margin: ~2 px at the
#: rig's distance, against :data:`~calibration.object_twin.render_model.MARGIN_PX`); a solve that
#: reaches that edge stops, the regions are made again where it stopped, and it goes on
REACH = (8.0, 1.5)
#: a solve starts with new regions when its start uses more than this share of the reach
RECENTRE_AT = 0.5
#: most re-made regions per solve
MAX_RECENTRES = 4
#: standard deviations beyond which a parameter counts as not determined
UNDETERMINED_STD = {"position_mm": 2.0, "rotation_deg": 0.5, "scale": 0.1}
POSE_NAMES = ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")
#: side of the tiles of the delete-one-tile jackknife [px]: several times the optics' blur and
#: a silhouette's misfit band, a few tiles over an object
BLOCK_PX = 12

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RefinedFit:
    """The refined object twin and its uncertainties."""

    offset: ObjectPose
    scales: dict[str, float]
    std_position_m: tuple[float, float, float]
    std_rotation_deg: tuple[float, float, float]
    std_scale: dict[str, float]
    determined: dict[str, bool]
    chi2_before: float
    chi2_after: float
    n_residuals: int
    evaluations: int
    #: each view's reduced chi-square at the solution (its residuals' mean square)
    chi2_per_view: tuple[float, ...] = ()
    #: the spread of the estimate over the views and over tiles of the views (the larger of the
    #: delete-one-view and the delete-one-tile jackknife, linearised at the solution):
    #: translations [m], angles [deg], scales [1]; inf where leaving a view out leaves a
    #: parameter undetermined
    jackknife_position_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    jackknife_rotation_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)
    jackknife_scale: dict[str, float] = field(default_factory=dict)
    line_steps: tuple[float, ...] = ()
    recentres: int = 0
    predicted: list[PredictedView] = field(repr=False, default_factory=list)
    correlation: np.ndarray | None = field(repr=False, default=None)

    def summary(self) -> dict:
        return {
            "offset": self.offset.model_dump(mode="json"),
            "std": {"position_m": list(self.std_position_m),
                    "rotation_deg": list(self.std_rotation_deg),
                    "reflectance_scale": dict(self.std_scale)},
            "determined": dict(self.determined),
            "reduced_chi2_before": self.chi2_before, "reduced_chi2_after": self.chi2_after,
            "reduced_chi2_per_view": list(self.chi2_per_view),
            "jackknife": {"position_m": list(self.jackknife_position_m),
                          "rotation_deg": list(self.jackknife_rotation_deg),
                          "reflectance_scale": dict(self.jackknife_scale)},
            "residuals": self.n_residuals, "evaluations": self.evaluations,
            "line_steps": list(self.line_steps), "recentred_regions": self.recentres,
        }


def offset_of(x: np.ndarray, lever_m: np.ndarray) -> np.ndarray:
    """The offset ``(t [mm], angles [deg])`` of the parameters ``(t' [mm], angles [deg])``, the
    translation ``t'`` taken at the pivot ``c + lever`` instead of the axis point ``c``:
    ``c + R (x - c) + t = p + R (x - p) + t'`` with ``t = t' - (R - I) lever``."""
    r = rotation_matrix_xyz_deg(tuple(float(v) for v in x[3:6]))
    t = np.asarray(x[:3], dtype=np.float64) - (r - np.eye(3)) @ lever_m * 1e3
    return np.r_[t, x[3:6]]


def pivot_parameters(offset: ObjectPose, lever_m: np.ndarray) -> np.ndarray:
    """Inverse of :func:`offset_of`: ``(t' [mm], angles [deg])`` of an offset."""
    r = rotation_matrix_xyz_deg(offset.rotation_deg)
    t = np.asarray(offset.position_m, dtype=np.float64) * 1e3
    return np.r_[t + (r - np.eye(3)) @ lever_m * 1e3, offset.rotation_deg]


def object_twin_of(x: np.ndarray, fitted: tuple[str, ...], fixed: dict[str, float],
                   lever_m: np.ndarray) -> ObjectTwinParameters:
    """The object twin of a parameter vector (translation at the pivot, angles, then the fitted
    scales)."""
    off = offset_of(x, lever_m)
    pose = ObjectPose(position_m=tuple(float(v) * 1e-3 for v in off[:3]),
                      rotation_deg=tuple(float(v) for v in off[3:6]))
    objects = {n: ObjectParameters(reflectance_scale=float(s)) for n, s in fixed.items()}
    objects.update({n: ObjectParameters(reflectance_scale=float(s))
                    for n, s in zip(fitted, x[6:], strict=True)})
    return ObjectTwinParameters(mount=MountParameters(pose_offset=pose), objects=objects)


def phasor_sigma(pred: PredictedView, capture: AveragedCapture, sensor: SensorParams,
                 spp: int, rel: float = 0.0) -> np.ndarray:
    """Standard deviation of each part of the averaged measured phasor less the prediction,
    (n_f, 2, H, W) [DN] (module docstring)."""
    g = sensor.adc_gain_e_per_dn
    # Each C_i = A_i - B_i: shot noise of both taps, read noise of both, their rounding.
    var_c = (pred.taps.sum(axis=2) / g + 2.0 * (sensor.read_noise_e / g) ** 2 + 2.0 / 12.0)
    var_sensor = np.stack([var_c[:, 0] + var_c[:, 2], var_c[:, 1] + var_c[:, 3]], axis=1)
    var = var_sensor / capture.n_frames + pred.mc_var * (1.0 / spp + 1.0 / MODEL_SPP)
    if rel > 0.0:
        var = var + (rel * np.abs(pred.phasor)[:, None]) ** 2
    return np.sqrt(var)


def residual_masks(captures: list[AveragedCapture], predicted: list[PredictedView],
                   regions: list[np.ndarray]) -> list[np.ndarray]:
    """Pixels of each view that enter the residual: the re-rendered region without what the
    camera flagged (above its amplitude threshold but invalid: saturated, SBI) or the twin
    saturates."""
    thr = ValidityThresholds().min_amplitude_dn
    return [reg & ~(~c.valid & (c.amplitude >= thr)) & ~p.saturated
            for c, p, reg in zip(captures, predicted, regions, strict=True)]


@dataclass
class _Problem:
    renderer: TwinRenderer
    measured: list[np.ndarray]
    masks: list[np.ndarray]
    sigma: list[np.ndarray]
    fitted: tuple[str, ...]
    fixed: dict[str, float]
    lever_m: np.ndarray
    evaluations: int = 0
    cache: dict = field(default_factory=dict)

    def predict(self, x: np.ndarray) -> list[PredictedView]:
        key = np.round(x, 9).tobytes()
        if key not in self.cache:
            if len(self.cache) > 16:
                self.cache.clear()
            self.cache[key] = self.renderer.predict(
                object_twin_of(x, self.fitted, self.fixed, self.lever_m))
            self.evaluations += 1
        return self.cache[key]

    def residual(self, x: np.ndarray) -> np.ndarray:
        out = []
        for zm, pred, m, sig in zip(self.measured, self.predict(x), self.masks, self.sigma,
                                    strict=True):
            d = zm - pred.phasor
            out.extend([(d.real / sig[:, 0])[:, m].ravel(), (d.imag / sig[:, 1])[:, m].ravel()])
        return np.concatenate(out)

    def pixel_blocks(self, block_px: int) -> list[np.ndarray]:
        """The rows of :meth:`residual` of each ``block_px`` square tile of each view's image
        (both parts, every frequency of the tile's pixels), tiles with no pixel left out."""
        groups, start = [], 0
        for zm, m in zip(self.measured, self.masks, strict=True):
            rows_px, cols_px = np.nonzero(m)  # the masked pixels in C order, as in residual
            n_px = rows_px.size
            tile = (rows_px // block_px) * (m.shape[1] // block_px + 1) + cols_px // block_px
            # row k of the view's block: part p, frequency f, pixel i -> ((p*n_f + f)*n_px + i)
            offsets = start + np.arange(2 * zm.shape[0])[:, None] * n_px
            for t in np.unique(tile):
                groups.append((offsets + np.flatnonzero(tile == t)[None, :]).ravel())
            start += 2 * zm.shape[0] * n_px
        return groups

    def view_slices(self) -> list[slice]:
        """Each view's rows of :meth:`residual` (and of the Jacobian), in the views' order."""
        out, start = [], 0
        for zm, m in zip(self.measured, self.masks, strict=True):
            n = 2 * zm.shape[0] * int(m.sum())
            out.append(slice(start, start + n))
            start += n
        return out

    def jacobian(self, x: np.ndarray, wide: bool = False) -> np.ndarray:
        """Forward differences of :func:`_steps` (a render per parameter): the solves'. ``wide``:
        the pose's columns by central differences :data:`WIDE_POSE_STEPS` times as wide (two
        renders each), the scales' as before (the residual is linear in them): the last solve's
        and the uncertainties' (module docstring)."""
        f0 = self.residual(x)
        steps = _steps(len(self.fitted))
        jac = np.empty((f0.size, x.size))
        for i, h in enumerate(steps):
            if wide and i < 6:
                hw = h * WIDE_POSE_STEPS
                xp, xm = x.copy(), x.copy()
                xp[i] += hw
                xm[i] -= hw
                jac[:, i] = (self.residual(xp) - self.residual(xm)) / (2.0 * hw)
                continue
            xi = x.copy()
            xi[i] += h
            jac[:, i] = (self.residual(xi) - f0) / h
        return jac


def _reach_used(x: np.ndarray, centre: np.ndarray) -> float:
    """The largest share of :data:`REACH` the pose of ``x`` uses from ``centre``."""
    reach = np.array([REACH[0]] * 3 + [REACH[1]] * 3)
    return float(np.max(np.abs(x[:6] - centre[:6]) / reach))


def _levenberg_marquardt(prob: _Problem, x: np.ndarray, max_iter: int, centre: np.ndarray,
                         wide: bool = False
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[float], bool]:
    """Levenberg-Marquardt (Marquardt's scaling: the damping times the diagonal of ``J^T J``)
    with a stretch along each accepted step: doubled (up to :data:`MAX_STRETCH`) while the cost
    keeps dropping. A Jacobian (one render per parameter) per iteration, a render per trial.
    The damping bends a step away from the weakly determined directions (a body's tilt against
    its reflectance, in the smoothed first solve) that an undamped step, cut to a length, would
    follow into another valley; a step longer than :data:`MAX_STEP` is damped, not cut. No step
    leaves the :data:`REACH` of ``centre``. Returns the
    solution, its residual, its Jacobian, the accepted step lengths (in multiples of the damped
    step) and whether the solve stopped at the reach's edge. ``wide``: the Jacobian's pose
    columns by wide central differences (:meth:`_Problem.jacobian`; the last solve's)."""
    steps = _steps(len(x) - 6)
    cap = np.array([MAX_STEP[0]] * 3 + [MAX_STEP[1]] * 3 + [MAX_STEP[2]] * (len(x) - 6))
    reach = np.array([REACH[0]] * 3 + [REACH[1]] * 3)
    r = prob.residual(x)
    cost = float(r @ r)
    jac = prob.jacobian(x, wide)
    taken = []
    at_edge = False
    damping = DAMPING[0]

    def trial(xa):
        try:
            ra = prob.residual(xa)
        except InvalidInputError:  # a scale beyond what the material allows (ks + kd > 1)
            return None, np.inf
        return ra, float(ra @ ra)

    for _ in range(max_iter):
        jtj, g = jac.T @ jac, jac.T @ r
        diag = np.maximum(np.diag(jtj), 1e-12 * max(1.0, float(np.max(np.diag(jtj)))))
        best = None
        while damping <= DAMPING[2]:
            try:
                dx = np.linalg.solve(jtj + damping * np.diag(diag), -g)
            except np.linalg.LinAlgError:
                damping *= DAMPING[1]
                continue
            longest = float(np.min(cap / np.maximum(np.abs(dx), 1e-12)))
            if longest < 1.0 and damping * DAMPING[1] <= DAMPING[2]:
                damping *= DAMPING[1]  # longer than an iteration may go: damp (no render)
                continue
            # the reach: x + a dx within centre +- reach, per pose parameter
            room = np.where(dx[:6] > 0, centre[:6] + reach - x[:6], x[:6] - (centre[:6] - reach))
            edge = float(np.min(np.maximum(room, 0.0) / np.maximum(np.abs(dx[:6]), 1e-12)))
            longest = min(longest, edge)
            a = min(1.0, longest)
            xa = x + a * dx
            ra, ca = trial(xa)
            if ca < cost:
                best = (a, xa, ra, ca)
                break
            damping *= DAMPING[1]
        if best is None:
            break
        while 2.0 * best[0] <= min(MAX_STRETCH, longest):
            xa = x + 2.0 * best[0] * dx
            ra, ca = trial(xa)
            if ca >= best[3]:
                break
            best = (2.0 * best[0], xa, ra, ca)
        if edge <= min(MAX_STRETCH, longest) and best[0] >= 0.5 * edge:
            # the cost kept dropping towards the reach's edge: go there, then new regions
            xe = x + edge * dx
            re, ce = trial(xe)
            if ce < best[3]:
                best = (edge, xe, re, ce)
            at_edge = True
        a, x, r, cost = best
        taken.append(a)
        log.debug("step %.3g (damping %.2g): chi2/n %.4g at %s", a, damping, cost / r.size,
                  np.array2string(x, precision=4))
        damping = max(DAMPING[0], damping / DAMPING[1] ** 2)
        jac = prob.jacobian(x, wide)
        if at_edge or np.all(np.abs(a * dx) <= CONVERGED * np.abs(steps)):
            break
    return x, r, jac, taken, at_edge


def _height_search(prob: _Problem, x: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The start moved along the turntable's axis to the lowest cost of a coarse grid
    (:data:`HEIGHT_SEARCH_MM`): ICP sees only vertical faces, so its height can be off by more
    than the silhouette's reach."""
    best, best_cost = x, float(np.sum(prob.residual(x) ** 2))
    half, step = HEIGHT_SEARCH_MM
    for dz in np.arange(-half, half + 1e-9, step):
        if dz == 0.0:
            continue
        xi = x.copy()
        xi[:3] += dz * axis
        try:
            c = float(np.sum(prob.residual(xi) ** 2))
        except InvalidInputError:
            continue
        if c < best_cost:
            best, best_cost = xi, c
    return best


def jackknife_covariance(jac: np.ndarray, r: np.ndarray,
                         groups: Sequence[slice | np.ndarray],
                         singular: str = "unbounded") -> np.ndarray:
    """The delete-one-group jackknife covariance of a least-squares solution, linearised at it.

    Leaving group ``g`` of residuals out (a view, a tile of a view) moves the Gauss-Newton
    solution by ``d_g = (J^T J - J_g^T J_g)^-1 J_g^T r_g`` (``J = dr/dx`` and ``r`` whitened, at
    the solution where ``J^T r = 0``, so the other groups' gradient is ``-J_g^T r_g``); the
    jackknife covariance is ``(n - 1) / n * sum_g (d_g - mean d)(d_g - mean d)^T`` (Efron and
    Stein). It measures how far the groups agree with each other, whatever the residual's noise
    model says: over views, a view the model gets wrong; over tiles, errors correlated across
    neighbouring pixels (the optics, a misfit silhouette), which the Jacobian's error, counting
    every pixel as independent, does not see.

    Where leaving a group out leaves some parameters undetermined (``J^T J - J_g^T J_g``
    singular along directions that involve them: an object only one view sees), those
    parameters' variances are inf, with no covariance (``singular="unbounded"``: the groups
    cannot cross-check them; the others keep theirs, from the least-norm move), or that group is
    passed over (``"skip"``: tiles, where the views' jackknife judges identifiability). Fewer
    than two groups counted: inf everywhere.
    """
    n_par = jac.shape[1]
    jtj = jac.T @ jac
    moves = []
    unbounded = np.zeros(n_par, dtype=bool)
    for g in groups:
        jg = jac[g]
        if jg.shape[0] == 0:
            continue
        a = jtj - jg.T @ jg
        if not np.all(np.isfinite(a)):
            unbounded[:] = True
            continue
        w, v = np.linalg.eigh(a)
        null = w <= 1e-12 * max(float(w.max()), 1e-300)
        if np.any(null):
            if singular == "skip":
                continue
            unbounded |= np.any(np.abs(v[:, null]) > 1e-6, axis=1)
        keep = ~null
        moves.append(v[:, keep] @ ((v[:, keep].T @ (jg.T @ r[g])) / w[keep]))
    if len(moves) < 2:
        return np.full((n_par, n_par), np.inf)
    cov = jackknife_covariance_of(np.array(moves))
    cov[unbounded, :] = 0.0
    cov[:, unbounded] = 0.0
    cov[unbounded, unbounded] = np.inf
    return cov


def conv_std(cov: np.ndarray, conv: np.ndarray) -> np.ndarray:
    """The standard deviations of ``conv @ x`` for ``x`` of covariance ``cov``: inf for a
    component that depends on a parameter of infinite variance, the others from the finite
    part."""
    unbounded = ~np.isfinite(np.diag(cov))
    finite = np.where(np.outer(~unbounded, ~unbounded), cov, 0.0)
    std = np.sqrt(np.clip(np.diag(conv @ finite @ conv.T), 0.0, None))
    std[np.any(conv[:, unbounded] != 0.0, axis=1)] = np.inf
    return std


def _steps(n_scales: int) -> np.ndarray:
    """The forward-difference steps (scales step down: a material allows ks + kd <= 1 only)."""
    return np.array([STEP_MM] * 3 + [STEP_DEG] * 3 + [-STEP_SCALE] * n_scales)


def refine_object_twin(
    renderer: TwinRenderer,
    captures: list[AveragedCapture],
    offset0: ObjectPose,
    pivot_m: np.ndarray,
    scales0: dict[str, float],
    fitted: tuple[str, ...],
    solves: tuple[tuple[float, int], ...] = SOLVES,
) -> RefinedFit:
    """Least squares of the pose and the ``fitted`` objects' scales (module docstring).

    ``scales0`` holds every mounted object's starting scale (the others stay there).
    """
    fixed = {n: s for n, s in scales0.items() if n not in fitted}
    lever = np.asarray(pivot_m, dtype=np.float64) - np.asarray(renderer.spec.turntable.axis_point_m)
    x = np.r_[pivot_parameters(offset0, lever), [scales0[n] for n in fitted]]
    axis = np.asarray(renderer.spec.turntable.axis_direction, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    measured = [measured_phasor(c) for c in captures]
    spp = renderer.settings.spp
    sensors = [v.sensor for v in renderer.views]
    prob = r = jac = None
    evaluations = recentres = 0
    line_steps: list[float] = []

    def problem(x: np.ndarray, rel: float, previous: _Problem | None) -> _Problem:
        """The problem with weights made at ``x``; ``previous`` (None after new regions) may
        hold the prediction at ``x`` already."""
        key = np.round(x, 9).tobytes()
        pred = previous.cache.get(key) if previous is not None else None
        if pred is None:
            pred = renderer.predict(object_twin_of(x, fitted, fixed, lever))
        sigma = [phasor_sigma(p, c, s, spp, rel)
                 for p, c, s in zip(pred, captures, sensors, strict=True)]
        masks = residual_masks(captures, pred, renderer.regions)
        prob = _Problem(renderer, measured, masks, sigma, fitted, fixed, lever)
        prob.cache[key] = pred
        return prob

    centre = x.copy()
    first = problem(x, solves[0][0], None)
    r0 = first.residual(x)
    chi2_before = float(r0 @ r0) / max(1, r0.size - x.size)
    x = _height_search(first, x, axis)
    evaluations += first.evaluations
    prob = first
    for rel, n_iter in solves:
        for _attempt in range(MAX_RECENTRES + 1):
            if _reach_used(x, centre) > RECENTRE_AT:
                renderer.recentre(object_twin_of(x, fitted, fixed, lever))
                centre = x.copy()
                recentres += 1
                prob = None  # its predictions are of the old regions
            prob = problem(x, rel, prob)
            x, r, jac, taken, at_edge = _levenberg_marquardt(prob, x, n_iter, centre)
            line_steps.extend(taken)
            evaluations += prob.evaluations
            if not at_edge:
                break
    assert prob is not None and r is not None and jac is not None
    # the last steps and the uncertainties with the pose's wide central differences
    before = prob.evaluations
    if at_edge:  # the recentres ran out: no more steps
        jac = prob.jacobian(x, wide=True)
    else:
        x, r, jac, taken, _ = _levenberg_marquardt(prob, x, WIDE_ITERATIONS, centre, wide=True)
        line_steps.extend(taken)
    evaluations += prob.evaluations - before
    dof = max(1, r.size - x.size)
    s2 = float(r @ r) / dof
    slices = prob.view_slices()
    chi2_per_view = tuple(float(np.mean(r[sl] ** 2)) if sl.stop > sl.start else float("nan")
                          for sl in slices)
    # to the offset's own parameters (translation at the axis point)
    conv = np.eye(x.size)
    for i in range(6):
        h = np.zeros(x.size)
        h[i] = 1e-3
        conv[:6, i] = (offset_of(x + h, lever) - offset_of(x - h, lever)) / 2e-3
    try:
        cov = s2 * conv @ np.linalg.inv(jac.T @ jac) @ conv.T
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        corr = cov / np.outer(std, std)
    except np.linalg.LinAlgError:
        std, corr = np.full(x.size, np.inf), None
    jk_views = conv_std(jackknife_covariance(jac, r, slices), conv)
    jk_tiles = conv_std(jackknife_covariance(jac, r, prob.pixel_blocks(BLOCK_PX), "skip"), conv)
    jk = np.maximum(jk_views, jk_tiles)
    determined = {}
    for i, name in enumerate(POSE_NAMES):
        limit = UNDETERMINED_STD["position_mm" if i < 3 else "rotation_deg"]
        determined[name] = bool(np.isfinite(std[i]) and std[i] <= limit)
    std_scale = {n: float(std[6 + i]) for i, n in enumerate(fitted)}
    for n, s in std_scale.items():
        determined[n] = bool(np.isfinite(s) and s <= UNDETERMINED_STD["scale"])
    twin = object_twin_of(x, fitted, fixed, lever)
    return RefinedFit(
        offset=twin.mount.pose_offset,
        scales={n: p.reflectance_scale for n, p in twin.objects.items()},
        std_position_m=tuple(float(v) * 1e-3 for v in std[:3]),
        std_rotation_deg=tuple(float(v) for v in std[3:6]),
        std_scale=std_scale, determined=determined, chi2_before=chi2_before,
        chi2_after=s2, n_residuals=int(r.size), evaluations=evaluations,
        chi2_per_view=chi2_per_view,
        jackknife_position_m=tuple(float(v) * 1e-3 for v in jk[:3]),
        jackknife_rotation_deg=tuple(float(v) for v in jk[3:6]),
        jackknife_scale={n: float(jk[6 + i]) for i, n in enumerate(fitted)},
        line_steps=tuple(line_steps), recentres=recentres,
        predicted=prob.predict(x), correlation=corr)
