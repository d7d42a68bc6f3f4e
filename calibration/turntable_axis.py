"""The turntable's axis and zero from board poses over a sweep.

Each view's board pose (from the intrinsics calibration, camera frame) becomes a world pose with
the camera's ``world_from_camera``. A board in fixture ``m`` at reported angle ``theta_i`` sits at

    W_i = A(theta_i) M_m,    A(theta) = rotation by theta about the axis (direction a, point c)

with ``M_m`` its pose at reported zero. The fixture's orientation at the *true* zero, ``F_m``, is
known (an index pin or jig; the simulated lab mounts it exactly), its position is not:
``M_m = [A(z) F_m | t_m]``. The axis (2 + 2 parameters), the zero offset ``z`` and every
``t_m`` (3 each) are fitted by least squares (scipy ``least_squares``): first the distance of
the board's corners between the model and each view's PnP pose, then, given the intrinsics,
the corners' reprojection error in the images (a bundle adjustment of the turntable model).
Reported angle + z = true angle. Each fixture's own zero (from its views alone) is reported as a
check.

With ``refine_intrinsics`` the last stage also frees the intrinsics and distortion (fx, fy, cx,
cy, k1, k2, p1, p2): one bundle adjustment of camera and turntable together. The views are then
tied by the turntable model (a few dozen parameters) instead of a free pose each (six per view),
which determines what a free-pose calibration leaves weak: the focal length against the boards'
distance (which places the axis along the line of sight) and the principal point against the
camera's rotation (which places it sideways).
The axis point reported is the axis' point closest to the nominal axis point.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from sim_core.camera import Intrinsics
from sim_core.errors import InvalidInputError
from sim_core.geometry import axis_angle_matrix

MIN_ANGLES = 3
MIN_SPAN_DEG = 20.0


@dataclass(frozen=True)
class TurntableAxisResult:
    """Axis (world frame), zero offset and residuals.

    Attributes
    ----------
    axis_point_m, axis_direction : (3,) float
    zero_offset_deg : float
        Reported angle + offset = true angle.
    rms_mm : float
        RMS distance of the board corners between fitted and measured poses.
    per_view_mm : dict
    zero_spread_deg : float
        Spread of the zero offset between fixtures (0 with one fixture).
    intrinsics : Intrinsics or None
        The intrinsics refined together with the turntable (``refine_intrinsics``), else None.
    reprojection_rms_px : float or None
        RMS of the corners' reprojection through the turntable model (with intrinsics given).
    poses : dict
        View name -> (rvec, tvec): the board in the camera frame as the turntable model places
        it (the same form as :class:`calibration.intrinsics.IntrinsicsResult`'s poses).
    parameter_names : tuple of str
        The names of the last stage's parameters: ``axis_u``, ``axis_v`` (the direction's tilt
        along two unit vectors normal to the nominal direction), ``point_u``, ``point_v`` [m]
        (the point's shift along them), ``zero_offset_deg``, each fixture's position
        (``<fixture>.x`` ...) and, with ``refine_intrinsics``, ``fx_px`` ... ``p2``.
    unit_covariance : (p, p) float or None
        ``(J^T J)^-1`` of the last stage's image residuals (with ``intrinsics``): the
        parameters' covariance for corners with 1 px of independent noise per coordinate
        (scale by the corners' variance); None without ``intrinsics``.
    residuals_px : dict
        View name -> (n, 2) reprojection residuals through the fitted model (with
        ``intrinsics``; else empty).
    basis : (2, 3) float
        The unit vectors ``u``, ``v`` of ``axis_u``/``point_u`` and ``axis_v``/``point_v`` (world
        frame).
    """

    axis_point_m: np.ndarray
    axis_direction: np.ndarray
    zero_offset_deg: float
    rms_mm: float
    per_view_mm: dict[str, float]
    zero_spread_deg: float
    intrinsics: Intrinsics | None = None
    reprojection_rms_px: float | None = None
    poses: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict, repr=False)
    parameter_names: tuple[str, ...] = ()
    unit_covariance: np.ndarray | None = field(default=None, repr=False)
    residuals_px: dict[str, np.ndarray] = field(default_factory=dict, repr=False)
    basis: np.ndarray | None = field(default=None, repr=False)

    def summary(self) -> dict:
        return {"axis_point_m": self.axis_point_m.tolist(),
                "axis_direction": self.axis_direction.tolist(),
                "zero_offset_deg": self.zero_offset_deg, "rms_mm": self.rms_mm,
                "worst_view_mm": max(self.per_view_mm.values()),
                "zero_spread_deg": self.zero_spread_deg,
                "reprojection_rms_px": self.reprojection_rms_px,
                "refined_intrinsics": None if self.intrinsics is None else {
                    "fx_px": self.intrinsics.fx_px, "fy_px": self.intrinsics.fy_px,
                    "cx_px": self.intrinsics.cx_px, "cy_px": self.intrinsics.cy_px,
                    "distortion": list(self.intrinsics.distortion)}}

    def plot(self, ax) -> str:
        names = list(self.per_view_mm)
        ax.bar(range(len(names)), [self.per_view_mm[n] for n in names])
        ax.set_xlabel("view")
        ax.set_ylabel("board pose residual [mm]")
        return f"Turntable model residual per view (RMS {self.rms_mm:.2f} mm)"


def _pose(rvec, tvec) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))[0]
    m[:3, 3] = np.asarray(tvec, dtype=np.float64).ravel()
    return m


def _basis(a):
    a = a / np.linalg.norm(a)
    t = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(a, t)
    u /= np.linalg.norm(u)
    return u, np.cross(a, u)


def _rotate(points, axis, point, angle_rad):
    r = axis_angle_matrix(axis, angle_rad)
    return (points - point) @ r.T + point


def _fixture_zero(views_meas, fixture, a, c, poses, wfc) -> float:
    """One fixture's zero: the mean rotation about the axis of its views' poses, turned back by
    their reported angles, against the fixture's known orientation [deg]."""
    angles = []
    for v, _ in views_meas:
        w = wfc @ _pose(*poses[v.name])
        back = axis_angle_matrix(a, -np.radians(v.turntable_angle_deg)) @ w[:3, :3]
        rv = Rotation.from_matrix(back @ fixture[:3, :3].T).as_rotvec()
        angles.append(np.degrees(np.dot(rv, a)))
    return float(np.median(angles))


def fit_turntable_axis(
    views,
    poses: dict[str, tuple[np.ndarray, np.ndarray]],
    world_from_camera: np.ndarray,
    fixtures_world_from_board: dict[str, np.ndarray],
    nominal_point_m=(0.0, 0.0, 0.0),
    nominal_direction=(0.0, 0.0, 1.0),
    intrinsics=None,
    refine_intrinsics: bool = False,
) -> TurntableAxisResult:
    """Fit the axis and zero (module docstring).

    Parameters
    ----------
    views : list of BoardView
        Their ``turntable_angle_deg`` and ``mounting``; only views with a pose are used.
    poses : dict
        View name -> (rvec, tvec), board in the camera frame.
    world_from_camera : (4, 4)
    fixtures_world_from_board : dict
        Mounting -> the board's known world pose at the true zero.
    intrinsics : Intrinsics, optional
        With it, the fit minimises the corners' reprojection error in the images (a bundle
        adjustment of the turntable model: every view's corners together, so the poses' weak
        depth direction is weighted as the images determine it); without it, the distance of
        the boards' corners between the model and the views' own poses.
    refine_intrinsics : bool
        Fit the intrinsics and distortion together with the turntable (module docstring); needs
        ``intrinsics`` as the start.
    """
    if refine_intrinsics and intrinsics is None:
        raise InvalidInputError("turntable.intrinsics", "refining the intrinsics together with "
                                "the turntable needs the calibrated intrinsics as a start")
    used = [v for v in views if v.name in poses]
    mounts = sorted({v.mounting for v in used})
    unknown = [m for m in mounts if m not in fixtures_world_from_board]
    if unknown:
        raise InvalidInputError("turntable.mounting",
                                f"no known fixture pose for mountings {unknown}")
    angles = sorted({round(v.turntable_angle_deg, 3) for v in used})
    if len(angles) < MIN_ANGLES:
        raise InvalidInputError("turntable.views", f"{len(angles)} distinct angles; at least "
                                f"{MIN_ANGLES} are needed to determine the axis")
    span = angles[-1] - angles[0]
    if span < MIN_SPAN_DEG:
        raise InvalidInputError("turntable.views", f"the sweep spans {span:.1f} deg; at least "
                                f"{MIN_SPAN_DEG:g} deg are needed to determine the axis")
    wfc = np.asarray(world_from_camera, dtype=np.float64)
    cfw = np.linalg.inv(wfc)
    measured = []
    for v in used:
        pts = v.object_points_m
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        ref = np.array([[lo[0], lo[1], 0], [hi[0], lo[1], 0], [hi[0], hi[1], 0],
                        [lo[0], hi[1], 0]])
        w = wfc @ _pose(*poses[v.name])
        measured.append((v, ref, ref @ w[:3, :3].T + w[:3, 3]))
    if intrinsics is not None:
        k = np.array([[intrinsics.fx_px, 0, intrinsics.cx_px],
                      [0, intrinsics.fy_px, intrinsics.cy_px], [0, 0, 1.0]])
        dist = np.asarray(intrinsics.distortion, dtype=np.float64)
    a0 = np.asarray(nominal_direction, dtype=np.float64)
    a0 /= np.linalg.norm(a0)
    c0 = np.asarray(nominal_point_m, dtype=np.float64)
    u0, v0 = _basis(a0)

    def unpack(x):
        a = a0 + x[0] * u0 + x[1] * v0
        a /= np.linalg.norm(a)
        c = c0 + x[2] * u0 + x[3] * v0
        zero = x[4]
        turn = axis_angle_matrix(a, np.radians(zero))
        ms = {}
        for i, m in enumerate(mounts):
            # The fixture's orientation at the true zero is known; its position is not.
            mm = np.eye(4)
            mm[:3, :3] = turn @ fixtures_world_from_board[m][:3, :3]
            mm[:3, 3] = x[5 + 3 * i: 8 + 3 * i]
            ms[m] = mm
        return a, c, ms, zero

    x0 = [0.0, 0.0, 0.0, 0.0, 0.0]
    for m in mounts:  # start each fixture at its nominal position
        x0 += list(fixtures_world_from_board[m][:3, 3])

    def world_points(x, v, pts):
        a, c, ms, _ = unpack(x)
        mm = ms[v.mounting]
        return _rotate(pts @ mm[:3, :3].T + mm[:3, 3], a, c, np.radians(v.turntable_angle_deg))

    def pose_residuals(x):
        return np.concatenate([(world_points(x, v, ref) - meas).ravel()
                               for v, ref, meas in measured])

    n_turntable = len(x0)

    def camera_of(x):
        if len(x) == n_turntable:
            return k, dist
        fx, fy, cx, cy, k1, k2, p1, p2 = x[n_turntable:]
        return (np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]),
                np.array([k1, k2, p1, p2, 0.0]))

    def image_residuals(x):
        kk, dd = camera_of(x)
        out = []
        for v in used:
            pw = world_points(x, v, v.object_points_m)
            pc = pw @ cfw[:3, :3].T + cfw[:3, 3]
            img, _ = cv2.projectPoints(pc, np.zeros(3), np.zeros(3), kk, dd)
            out.append((img.reshape(-1, 2) - v.image_points_px).ravel())
        return np.concatenate(out)

    sol = least_squares(pose_residuals, np.asarray(x0), method="lm", x_scale="jac")
    refined = None
    reprojection_rms = None
    unit_cov = None
    residuals: dict[str, np.ndarray] = {}
    if intrinsics is not None:
        sol = least_squares(image_residuals, sol.x, method="lm", x_scale="jac")
        if refine_intrinsics:
            start = np.concatenate([sol.x, [intrinsics.fx_px, intrinsics.fy_px,
                                            intrinsics.cx_px, intrinsics.cy_px],
                                    np.asarray(intrinsics.distortion, dtype=np.float64)[:4]])
            sol = least_squares(image_residuals, start, method="lm", x_scale="jac")
            kk, dd = camera_of(sol.x)
            refined = Intrinsics(intrinsics.width_px, intrinsics.height_px, float(kk[0, 0]),
                                 float(kk[1, 1]), float(kk[0, 2]), float(kk[1, 2]),
                                 tuple(float(v) for v in dd))
        final = image_residuals(sol.x)
        reprojection_rms = float(np.sqrt(np.mean(final**2) * 2.0))
        # The covariance of the last stage (the Jacobian at the solution, 1 px of noise).
        unit_cov = np.linalg.pinv(sol.jac.T @ sol.jac)
        split = np.cumsum([2 * len(v.object_points_m) for v in used])[:-1]
        residuals = {v.name: r.reshape(-1, 2)
                     for v, r in zip(used, np.split(final, split), strict=True)}
    a, c, _, zero = unpack(sol.x[:n_turntable])
    model_poses = {}
    for v in used:
        mm = unpack(sol.x[:n_turntable])[2][v.mounting]
        w = np.eye(4)
        w[:3, :3] = axis_angle_matrix(a, np.radians(v.turntable_angle_deg)) @ mm[:3, :3]
        w[:3, 3] = _rotate(mm[:3, 3][None, :], a, c, np.radians(v.turntable_angle_deg))[0]
        cfb = cfw @ w
        model_poses[v.name] = (cv2.Rodrigues(cfb[:3, :3])[0].ravel(), cfb[:3, 3].copy())
    if np.dot(a, a0) < 0:
        a = -a
    res = pose_residuals(sol.x[:n_turntable]).reshape(len(measured), -1, 3)
    per_view = {v.name: float(np.sqrt(np.mean(np.sum(r**2, axis=1)))) * 1e3
                for (v, _, _), r in zip(measured, res, strict=True)}
    # Each fixture's own zero (its fitted orientation against the known one), as a check.
    zeros = []
    for m in mounts:
        wm = [(v, meas) for v, _, meas in measured if v.mounting == m]
        zeros.append(_fixture_zero(wm, fixtures_world_from_board[m], a, c, poses, wfc))
    # The axis' point closest to the nominal point.
    point = c + np.dot(c0 - c, a) * a
    return TurntableAxisResult(
        axis_point_m=point, axis_direction=a, zero_offset_deg=float(zero),
        rms_mm=float(np.sqrt(np.mean(np.sum(res**2, axis=2)))) * 1e3, per_view_mm=per_view,
        zero_spread_deg=float(np.ptp(zeros)) if len(zeros) > 1 else 0.0,
        intrinsics=refined, reprojection_rms_px=reprojection_rms, poses=model_poses,
        parameter_names=_parameter_names(mounts, refine_intrinsics and intrinsics is not None),
        unit_covariance=unit_cov, residuals_px=residuals, basis=np.stack([u0, v0]))


#: the camera's parameters of the joint adjustment, in its order
CAMERA_PARAMETERS = ("fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "p1", "p2")


def _parameter_names(mounts: list[str], with_camera: bool) -> tuple[str, ...]:
    names = ["axis_u", "axis_v", "point_u", "point_v", "zero_offset_deg"]
    names += [f"{m}.{c}" for m in mounts for c in "xyz"]
    return tuple(names + list(CAMERA_PARAMETERS if with_camera else ()))
