"""The preset's photometric level, measured: the ground-test object's grey and the board's whites.

docs/camera-presets.md quotes the numbers this module prints; rerun it after changing a default:

    python -m tests.sim_core.photometry_levels

Object grey: mean of the 8-bit grey image (the frame's grey full scale, 2^(adc_bits-1) DN) over
the satellite model's pixels (body and solar panels, the pedestal left out as the seed's
measured image masks everything but the model), ground-test example at its nominal 1 m, the
direct integrator and the default sensor with noise. Board whites: the calibration sequence's
default ChArUco board (Lambertian 0.85 / 0.04) on each default fixture at turntable 0 deg,
solar simulator off: amplitude and the fuller tap on its white squares.
"""

from __future__ import annotations

import numpy as np

from calibration.fixtures import board_object
from calibration.photometry import white_square_mask
from calibration.rig_sequence import DEFAULT_BOARD, DEFAULT_FIXTURES
from sim_core import frame_io
from sim_core.pipeline import simulate
from sim_core.render import RenderSettings
from sim_core.render_request import RenderRequest
from sim_core.scene import build_scene
from sim_core.scene_spec import load_scene_spec
from tests.sim_core.scenes import EXAMPLES

GROUND_TEST = EXAMPLES / "satellite_ground_test.yaml"
#: the satellite model's parts (the seed's measured image shows the model only)
MODEL_PARTS = ("body", "panel_left", "panel_right")
#: a full turn in 10 deg steps: every pose the turntable gives the model the same weight
SWEEP_DEG = tuple(float(a) for a in range(0, 360, 10))


def object_grey(angle_deg: float, spp: int = 2, seed: int = 0) -> dict[str, float]:
    """Grey statistics of the model's pixels in one ground-test frame at ``angle_deg``."""
    spec = load_scene_spec(GROUND_TEST)
    scene = build_scene(spec, base_dir=GROUND_TEST.parent, turntable_deg=angle_deg)
    frame = simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=spp, seed=seed)))
    grey, _ = frame_io.grey_preview_8bit(frame.image.amplitude, frame.image.valid,
                                         frame.grey_full_scale)
    names = [o.name for o in spec.objects]
    model = np.isin(frame.light_field.object_id, [names.index(n) for n in MODEL_PARTS])
    return {
        "angle_deg": angle_deg,
        "grey_mean": float(grey[model].mean()),
        "grey_std": float(grey[model].std()),
        "amplitude_mean_dn": float(frame.image.amplitude[model].mean()),
        "saturated_px": int(frame.raw.saturated[model].sum()),
        "model_px": int(model.sum()),
    }


def sweep_grey(angles_deg=SWEEP_DEG, spp: int = 2) -> tuple[list[dict], float]:
    """:func:`object_grey` over ``angles_deg`` and the mean of the per-frame grey means."""
    rows = [object_grey(a, spp) for a in angles_deg]
    return rows, float(np.mean([r["grey_mean"] for r in rows]))


def board_whites(spp: int = 16) -> list[dict[str, float]]:
    """Amplitude and fuller-tap level on the default board's white squares, per fixture."""
    spec = load_scene_spec(GROUND_TEST)
    rows = []
    for fixture in DEFAULT_FIXTURES:
        obj = board_object(DEFAULT_BOARD, fixture, spec)
        board_spec = spec.model_copy(update={
            "objects": [o for o in spec.objects if not o.on_turntable] + [obj]})
        scene = build_scene(board_spec, GROUND_TEST.parent, turntable_deg=0.0, solar_suns=0.0)
        frame = simulate(scene, RenderRequest(RenderSettings(integrator="direct", spp=spp, seed=1)))
        amp = frame.image.amplitude
        white = white_square_mask(amp)
        taps = frame.raw.taps  # (n_f, 4, 2, H, W) DN
        fuller = taps.max(axis=(0, 1, 2))
        top = 2 ** scene.sensor.adc_bits - 1
        rows.append({
            "fixture": fixture.name,
            "white_amplitude_dn": float(np.median(amp[white])),
            "white_grey": float(np.median(amp[white]) / frame.grey_full_scale * 255.0),
            "fuller_tap_dn": float(np.percentile(fuller[white], 99)),
            "adc_top_dn": float(top),
            "saturated_white_px": int(frame.raw.saturated[white].sum()),
        })
    return rows


def main() -> None:
    rows, mean = sweep_grey()
    print("ground test, satellite model at 1 m (direct, 2 spp, default sensor):")
    for r in rows:
        print(f"  turntable {r['angle_deg']:5.1f} deg: grey mean {r['grey_mean']:6.1f} "
              f"(std {r['grey_std']:5.1f}), amplitude {r['amplitude_mean_dn']:7.1f} DN, "
              f"saturated {r['saturated_px']} of {r['model_px']} px")
    print(f"  mean over the full turn: {mean:.1f} / 255")
    print("calibration board (default ChArUco, Lambertian 0.85 / 0.04), solar simulator off:")
    for r in board_whites():
        print(f"  {r['fixture']:8s}: white amplitude {r['white_amplitude_dn']:6.1f} DN "
              f"(grey {r['white_grey']:5.1f}), fuller tap p99 {r['fuller_tap_dn']:6.1f} DN "
              f"of {r['adc_top_dn']:.0f}, saturated {r['saturated_white_px']} px")


if __name__ == "__main__":
    main()
