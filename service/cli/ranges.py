"""The allowed ranges of the numeric options (:func:`service.cli.common.number_option`).

A range that lives in a light module is taken from it: the scene's render settings
(:class:`sim_core.scene_spec.RenderSpec`), the solar simulator's levels
(:data:`sim_core.lights.SUNS_RANGE`), the turntable's addresses. A range whose home is too heavy
to import when the command line starts (``service.settings``, ``service.lab.requests`` and
``sim_core.adaptive`` bring the renderer and numba: seconds before ``--help`` could answer) is
written here beside the name of its home, and
``tests/service/cli/test_numeric_options.py::test_each_copied_range_is_that_of_its_home`` checks
every such copy against its home.
"""

from __future__ import annotations

from calibration.angles import SWEEP_STEP_RANGE_DEG
from drivers.turntable import ADDRESS_RANGE
from service.cli.common import Range, field_range
from sim_core.lights import SUNS_RANGE
from sim_core.scene_spec import RenderSpec

# -- from their homes --------------------------------------------------------------------------
SPP = field_range(RenderSpec, "spp")
MAX_BOUNCES = field_range(RenderSpec, "max_bounces")
SEED = field_range(RenderSpec, "seed")
TURNTABLE_ADDRESS = Range(*ADDRESS_RANGE)
#: the board sweep's step (calibration.angles: the command line's and the service's rule)
SWEEP_STEP = Range(*SWEEP_STEP_RANGE_DEG, unit="deg")
#: a solar simulator level, or 0 for off
SOLAR_SUNS_OR_OFF = Range(*SUNS_RANGE, unit="sun", also=(0.0,))

# -- copies, each checked against its home by the tests ----------------------------------------
#: sim_core.adaptive.NOISE_FRACTION_RANGE
NOISE_FRACTION = Range(0.05, 2.0)
#: sim_core.adaptive.render_adaptive's target_range_error_mm and time_budget_s
TARGET_RANGE_ERROR = Range(0.0, 1e6, lo_open=True, hi_open=True, unit="mm")
TIME_BUDGET = Range(0.0, 86_400.0, lo_open=True, unit="s")
#: service.lab.requests.Angle: a turntable angle as the API takes it (the stage's own software
#: limits are checked when the rig moves or the scene is built)
TURNTABLE_DEG = Range(-360.0, 360.0, unit="deg")
#: service.lab.requests.MaskSpec.near_m and far_m
MASK_DISTANCE = Range(0.0, 1000.0, unit="m")
#: calibration.rig_sequence.FRAMES_PER_VIEW_RANGE (the plan builder's)
FRAMES_PER_VIEW = Range(1, 64)
#: calibration.solar.REFERENCE_SUNS_RANGE: a reference cell's reading at a set level of 1 sun
REFERENCE_SUNS = Range(0.0, 5.0, lo_open=True, unit="sun")
#: service.lab.requests.ObjectFitIn.frames
FIT_FRAMES = Range(1, 256)
#: service.settings.Settings: port, workers, sim_threads, camera_spp, camera_seed
PORT = Range(0, 65535)
WORKERS = Range(1, 64)
THREADS = Range(1, 256)
CAMERA_SPP = Range(1, 4096)
CAMERA_SEED = Range(0, 2**31 - 1)
#: 1 to the defaults of service.settings.Settings.max_poses, max_repeats and max_spp: the limits
#: of the service ``toftwin bench campaign`` runs
BENCH_POSES = Range(1, 720)
BENCH_REPEATS = Range(1, 100)
BENCH_SPP = Range(1, 256)
#: service.lab.requests.TURNING_SPEED_RANGE_DEG_S (CampaignCreate.turning_deg_s)
TURNING_SPEED = Range(0.1, 20.0, unit="deg/s")
#: the angle between the poses of ``toftwin bench turning``
TURNING_STEP = Range(0.5, 60.0, unit="deg")

# -- the command line's own ------------------------------------------------------------------
#: the effect planner's tolerance (sim_core.plan takes any positive value)
EFFECT_TOLERANCE = Range(0.0, 1e4, lo_open=True, unit="mm")
PREVIEW_SCALE = Range(1, 8)
#: calibration.rig_material.MaterialSweepPlan: size_m and frames_per_state
SAMPLE_SIZE = Range(0.02, 0.5, unit="m")
FRAMES_PER_STATE = Range(2, 64)
#: calibration.brdf.FitSettings.outlier_relative_error
OUTLIER_THRESHOLD = Range(0.0, 10.0, lo_open=True)
#: the seed of RANSAC and differential evolution (numpy's legacy seeds are 32-bit)
FIT_SEED = Range(0, 2**32 - 1)
#: a goniometer band: ultraviolet to far infrared
WAVELENGTH = Range(100.0, 100_000.0, unit="nm")
BENCH_ROUNDS = Range(1, 100)
#: a board's square or marker side in ``calibrate intrinsics`` (a printed board: above 0, at
#: most a metre)
BOARD_SIDE_MM = Range(0.0, 1000.0, lo_open=True, unit="mm")
#: ``toftwin record --frames``: frames at one rig state (service.lab.requests.CampaignPoseIn.
#: repeats)
RECORD_FRAMES = Range(1, 10000)
#: ``toftwin replay --spp``: the simulations' samples per pixel (service.settings.Settings.
#: max_spp's default)
REPLAY_SPP = Range(1, 256)
