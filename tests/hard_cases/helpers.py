"""Scene builders and frame checks shared by the hard cases.

Scenes are built from dicts through the public scene format (``parse_scene_spec`` +
``build_scene``), as a user would write them; cameras are small (32 x 24 px unless a case
needs otherwise) so that the whole folder stays fast.
"""

from __future__ import annotations

import numpy as np

from sim_core.camera import pixel_centre_grid
from sim_core.pipeline import SimulatedFrame
from sim_core.render import RenderSettings
from sim_core.scene import Scene, build_scene
from sim_core.scene_spec import parse_scene_spec
from sim_core.tof import ambiguity_range_m, common_frequency_hz

#: optics without the MTF chain: closed forms compare against the unfiltered light field
NO_MTF = {"diffraction": False, "pixel_aperture": False}
#: one sample through every pixel centre: closed forms hold per pixel
CENTRE = RenderSettings(integrator="direct", spp=1, jitter=False)
#: a cheap but complete path-traced frame (jitter, NEE, BRDF sampling, Russian roulette)
PATH = RenderSettings(integrator="path", spp=4, max_bounces=3, seed=11)
#: radiant intensity of a 1 W isotropic source [W/sr]
I_1W = 1.0 / (4.0 * np.pi)


def camera(position, look_at, *, width=32, height=24, f_px=30.0, up=(0.0, 0.0, 1.0), **extra):
    """Camera block of a scene dict: look-at pose, small image, square pixels."""
    return {
        "pose": {"position_m": [float(c) for c in position],
                 "look_at_m": [float(c) for c in look_at], "up": [float(c) for c in up]},
        "width_px": width, "height_px": height, "fx_px": f_px, "fy_px": f_px, **extra,
    }


def lambert(albedo: float) -> dict:
    return {"kind": "lambertian", "params": {"albedo": albedo}}


def rectangle(name, size_m, material, position_m, rotation_deg=(0.0, 0.0, 0.0)) -> dict:
    """A rectangle object (normal +z before the rotation)."""
    return {"name": name, "mesh": {"kind": "rectangle", "size_m": [float(s) for s in size_m]},
            "material": material,
            "pose": {"position_m": [float(c) for c in position_m],
                     "rotation_deg": [float(a) for a in rotation_deg]}}


def build(cam: dict, objects: list, *, power_w: float = 1.0, optics=None, **extra) -> Scene:
    """A posed scene from its parts; no MTF unless ``optics`` says otherwise."""
    spec = {"camera": cam, "illumination": {"power_w": power_w, **extra.pop("light", {})},
            "objects": objects, "optics": NO_MTF if optics is None else optics, **extra}
    return build_scene(parse_scene_spec(spec))


def pixel_rays(scene: Scene) -> np.ndarray:
    """World-frame unit directions through every pixel centre, (H * W, 3), row-major."""
    return scene.camera.pixel_directions_world(*pixel_centre_grid(scene.camera.intrinsics))


def unambiguous_range_m(frequencies_hz) -> float:
    """Range up to which a frame's reconstruction is unique: c / 2f, or c / 2 gcd(f1, f2)."""
    f = [float(x) for x in frequencies_hz]
    if len(f) >= 2:
        return ambiguity_range_m(common_frequency_hz(f[0], f[1]))
    return ambiguity_range_m(f[0])


def assert_frame_bounded(frame: SimulatedFrame) -> None:
    """Finite, physically bounded outputs and a consistent validity mask.

    Amplitude and intensity finite and >= 0; every phase in [0, 2 pi); a valid pixel has a
    finite range in [0, unambiguous range] and is neither saturated nor in the SBI limit; an
    invalid pixel has NaN range and depth; the light field is finite with |phasor| <= DC.
    """
    img, lf = frame.image, frame.light_field
    for arr in (img.amplitude, img.intensity, img.phase_rad, lf.dc_active, lf.dc_ambient,
                lf.phasor):
        assert np.all(np.isfinite(arr))
    assert np.all(img.amplitude >= 0.0) and np.all(img.intensity >= 0.0)
    assert np.all(lf.dc_active >= 0.0) and np.all(lf.dc_ambient >= 0.0)
    # |sum of w e^{-i phi}| <= sum of w, up to rounding of the sums
    assert np.all(np.abs(lf.phasor) <= lf.dc_active * (1.0 + 1e-9) + 1e-300)
    assert np.all((img.phase_rad >= 0.0) & (img.phase_rad < 2.0 * np.pi))
    u = unambiguous_range_m(img.frequencies_hz)
    r = img.range_m[img.valid]
    assert np.all(np.isfinite(r)) and np.all((r >= 0.0) & (r <= u))
    assert np.all(np.isnan(img.range_m[~img.valid]))
    assert np.all(np.isnan(img.depth_z_m[~img.valid]))
    if frame.raw is not None:
        assert np.all(np.isfinite(frame.raw.phase_images))
        assert np.all(np.isfinite(frame.raw.intensity))
        assert not np.any(img.valid & (frame.raw.saturated | frame.raw.sbi_limit))


def assert_stable(
    a: SimulatedFrame,
    b: SimulatedFrame,
    *,
    range_tol_m: float,
    radiance_rel: float,
    dn_tol: float = 1.0,
    mask_changes: int = 0,
) -> None:
    """Two frames of inputs that differ by a tiny perturbation differ by a small amount.

    ``range_tol_m`` bounds the change of range of pixels valid in both (on the circle of the
    unambiguous range), ``radiance_rel`` the change of the light field relative to its peak,
    ``dn_tol`` the change of the raw correlation images [DN] (the same seed draws the same
    noise, so only a draw that lands on a rounding edge may move by one step), and
    ``mask_changes`` the number of pixels whose validity may flip (0: none).
    """
    la, lb = a.light_field, b.light_field
    scale = max(float(np.max(la.dc_active)), float(np.max(la.dc_ambient)), 1e-300)
    assert np.max(np.abs(la.dc_active - lb.dc_active)) <= radiance_rel * scale
    assert np.max(np.abs(la.dc_ambient - lb.dc_ambient)) <= radiance_rel * scale
    assert np.max(np.abs(la.phasor - lb.phasor)) <= radiance_rel * scale
    ia, ib = a.image, b.image
    assert int(np.sum(ia.valid != ib.valid)) <= mask_changes
    both = ia.valid & ib.valid
    if both.any():
        u = unambiguous_range_m(ia.frequencies_hz)
        d = np.abs(ia.range_m[both] - ib.range_m[both])
        # A raw value that lands on a rounding edge moves by one step (dn_tol): that turns the
        # phasor (2 x amplitude long) by up to dn_tol / (2 amplitude) rad.
        flip_m = u / (2.0 * np.pi) * dn_tol / (2.0 * np.maximum(ia.amplitude[both], 1e-300))
        tol = range_tol_m + (flip_m if a.raw is not None else 0.0)
        assert np.all(np.minimum(d, u - d) <= tol)
    if a.raw is not None and b.raw is not None:
        assert np.max(np.abs(a.raw.phase_images - b.raw.phase_images)) <= dn_tol * 2.0


