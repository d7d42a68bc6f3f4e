"""Mount pose and reflectance scales together, by least squares against rendered views.

ICP (:mod:`calibration.object_twin.pose`) leaves the height along the turntable's axis to the
silhouette (every face the camera sees is vertical), and its point-to-plane residuals carry the
few-millimetre biases that blur and mixed pixels put into the measured ranges near edges. This
step compares the measured phasors with the twin's rendered ones instead
(:mod:`calibration.object_twin.render_model`: the same optics, sensor and depth errors, so those
effects are in both): the residual of every pixel in and around the mounted objects,

    r = (z_measured - z_predicted(pose, scales)) / sigma,   sigma^2 = sigma_0^2 + (rel |z_m|)^2

(``sigma_0`` the averaged frames' noise, ``rel`` = :data:`MODEL_REL_ERROR` the renders' and
materials' share: a bright specular face must not outweigh the rest), real and imaginary parts,
is minimised (soft-L1 loss: a glossy interreflection is Monte Carlo noise in any render) over
the offset (3 translations [mm], 3 extrinsic xyz angles [deg], the reality's
convention) and the determined objects' scales with scipy's trust-region least squares. The
Jacobian is by forward differences of renders with a fixed seed. A coarse search along the axis
first puts the height within the silhouette's reach (a pixel is about 4.7 mm at 1 m).

Uncertainties: ``(J^T J)^-1`` scaled by the residual variance. A parameter whose standard
deviation exceeds its limit (:data:`UNDETERMINED_STD`) is reported as not determined.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.optimize import least_squares

from calibration.object_twin.render_model import PredictedView, TwinRenderer
from sim_core.scene_spec import ObjectPose
from sim_core.twin_file import MountParameters, ObjectParameters, ObjectTwinParameters

#: share of a pixel's measured phasor the model may be off by (renders, materials) [1]
MODEL_REL_ERROR = 0.05
#: forward-difference steps: translations [mm], rotations [deg], scales [1]
STEP_MM, STEP_DEG, STEP_SCALE = 0.5, 0.1, 0.02
#: pixels around the predicted objects that enter the residual (the silhouette's reach) [px]
MARGIN_PX = 4
#: the coarse search along the axis: half-width and step [mm]
HEIGHT_SEARCH_MM = (10.0, 2.0)
#: soft-L1 loss scale [sigma] (glossy interreflections are Monte Carlo fireflies in a render)
ROBUST_SCALE = 3.0
#: residuals beyond this [sigma] are left out of the covariance
OUTLIER_SIGMA = 10.0
#: most residual evaluations of the trust-region solve (each followed by a Jacobian)
MAX_EVALUATIONS = 15
#: standard deviations beyond which a parameter counts as not determined
UNDETERMINED_STD = {"position_mm": 2.0, "rotation_deg": 0.5, "scale": 0.1}
POSE_NAMES = ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")


@dataclass(frozen=True)
class RefinedFit:
    """The refined object twin and its uncertainties."""

    offset: ObjectPose
    scales: dict[str, float]
    std_position_m: tuple[float, float, float]
    std_rotation_deg: tuple[float, float, float]
    std_scale: dict[str, float]
    determined: dict[str, bool]
    rms_before: float
    rms_after: float
    n_residuals: int
    renders: int
    height_search_mm: float
    correlation: np.ndarray = field(repr=False, default=None)

    def summary(self) -> dict:
        return {
            "offset": self.offset.model_dump(mode="json"),
            "std": {"position_m": list(self.std_position_m),
                    "rotation_deg": list(self.std_rotation_deg),
                    "reflectance_scale": dict(self.std_scale)},
            "determined": dict(self.determined),
            "weighted_rms_before": self.rms_before, "weighted_rms_after": self.rms_after,
            "residuals": self.n_residuals, "renders": self.renders,
            "height_after_search_mm": self.height_search_mm,
        }


def object_twin_of(x: np.ndarray, fitted: tuple[str, ...], fixed: dict[str, float]
                   ) -> ObjectTwinParameters:
    """The object twin of a parameter vector (offset, then the fitted scales)."""
    pose = ObjectPose(position_m=tuple(float(v) * 1e-3 for v in x[:3]),
                      rotation_deg=tuple(float(v) for v in x[3:6]))
    objects = {n: ObjectParameters(reflectance_scale=float(s)) for n, s in fixed.items()}
    objects.update({n: ObjectParameters(reflectance_scale=float(s))
                    for n, s in zip(fitted, x[6:], strict=True)})
    return ObjectTwinParameters(mount=MountParameters(pose_offset=pose), objects=objects)


@dataclass
class _Problem:
    renderer: TwinRenderer
    measured: list[np.ndarray]
    regions: list[np.ndarray]
    sigma: list[np.ndarray]
    fitted: tuple[str, ...]
    fixed: dict[str, float]
    cache: dict = field(default_factory=dict)

    def predict(self, x: np.ndarray) -> list[PredictedView]:
        key = np.round(x, 9).tobytes()
        if key not in self.cache:
            if len(self.cache) > 64:
                self.cache.clear()
            self.cache[key] = self.renderer.predict(object_twin_of(x, self.fitted, self.fixed))
        return self.cache[key]

    def residual(self, x: np.ndarray) -> np.ndarray:
        out = []
        for zm, pred, reg, sig in zip(self.measured, self.predict(x), self.regions, self.sigma,
                                      strict=True):
            r = np.where(pred.saturated, 0.0, (zm - pred.phasor) / sig)[reg]
            out.extend([r.real, r.imag])
        return np.concatenate(out)

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        f0 = self.residual(x)
        steps = np.array([STEP_MM] * 3 + [STEP_DEG] * 3 + [STEP_SCALE] * len(self.fitted))
        jac = np.empty((f0.size, x.size))
        for i, h in enumerate(steps):
            xi = x.copy()
            xi[i] += h
            jac[:, i] = (self.residual(xi) - f0) / h
        return jac


def fit_regions(measured_flagged: list[np.ndarray], predicted: list[PredictedView],
                mounted_ids: list[int]) -> list[np.ndarray]:
    """Pixels of each view that enter the residual: the predicted mounted objects, grown by
    :data:`MARGIN_PX`, without the pixels the camera flagged."""
    out = []
    for flagged, pred in zip(measured_flagged, predicted, strict=True):
        objs = np.isin(pred.object_id, mounted_ids)
        out.append(ndimage.binary_dilation(objs, iterations=MARGIN_PX) & ~flagged)
    return out


def refine_object_twin(
    renderer: TwinRenderer,
    measured: list[np.ndarray],
    regions: list[np.ndarray],
    noise_dn: list[float],
    offset0: ObjectPose,
    scales0: dict[str, float],
    fitted: tuple[str, ...],
    axis_direction: np.ndarray,
) -> RefinedFit:
    """Least squares of the pose and the ``fitted`` objects' scales (module docstring).

    ``scales0`` holds every mounted object's starting scale (the others stay there);
    ``noise_dn`` is each view's noise of an averaged phasor component [DN].
    """
    sigma = [np.sqrt(s**2 + (MODEL_REL_ERROR * np.abs(zm)) ** 2)
             for zm, s in zip(measured, noise_dn, strict=True)]
    fixed = {n: s for n, s in scales0.items() if n not in fitted}
    prob = _Problem(renderer, measured, regions, sigma, fitted, fixed)
    x = np.array([*(v * 1e3 for v in offset0.position_m), *offset0.rotation_deg,
                  *(scales0[n] for n in fitted)], dtype=np.float64)
    r0 = prob.residual(x)
    rms_before = float(np.sqrt(np.mean(r0**2)))
    # Coarse search along the axis (the height ICP cannot see).
    axis = np.asarray(axis_direction, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    half, step = HEIGHT_SEARCH_MM
    best, best_cost = x, float(r0 @ r0)
    for dz in np.arange(-half, half + 1e-9, step):
        xi = x.copy()
        xi[:3] += dz * axis
        r = prob.residual(xi)
        if float(r @ r) < best_cost:
            best, best_cost = xi, float(r @ r)
    height = float((best[:3] - x[:3]) @ axis)
    lo = np.r_[np.full(6, -np.inf), np.full(len(fitted), 0.05)]
    hi = np.r_[np.full(6, np.inf), np.full(len(fitted), 10.0)]
    sol = least_squares(prob.residual, best, jac=prob.jacobian, bounds=(lo, hi), method="trf",
                        x_scale=np.r_[np.ones(6), np.full(len(fitted), 0.05)],
                        loss="soft_l1", f_scale=ROBUST_SCALE, xtol=1e-4, ftol=1e-6,
                        max_nfev=MAX_EVALUATIONS)
    x = sol.x
    r = prob.residual(x)
    jac = prob.jacobian(x)
    inlier = np.abs(r) <= OUTLIER_SIGMA
    r, jac = r[inlier], jac[inlier]
    dof = max(1, r.size - x.size)
    s2 = float(r @ r) / dof
    try:
        cov = s2 * np.linalg.inv(jac.T @ jac)
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        corr = cov / np.outer(std, std)
    except np.linalg.LinAlgError:
        std, corr = np.full(x.size, np.inf), None
    determined = {}
    for i, name in enumerate(POSE_NAMES):
        limit = UNDETERMINED_STD["position_mm" if i < 3 else "rotation_deg"]
        determined[name] = bool(np.isfinite(std[i]) and std[i] <= limit)
    std_scale = {n: float(std[6 + i]) for i, n in enumerate(fitted)}
    for n, s in std_scale.items():
        determined[n] = bool(np.isfinite(s) and s <= UNDETERMINED_STD["scale"])
    twin = object_twin_of(x, fitted, fixed)
    return RefinedFit(
        offset=twin.mount.pose_offset,
        scales={n: p.reflectance_scale for n, p in twin.objects.items()},
        std_position_m=tuple(float(v) * 1e-3 for v in std[:3]),
        std_rotation_deg=tuple(float(v) for v in std[3:6]),
        std_scale=std_scale, determined=determined, rms_before=rms_before,
        rms_after=float(np.sqrt(np.mean(r**2))), n_residuals=int(r.size),
        renders=renderer.renders, height_search_mm=height, correlation=corr)
