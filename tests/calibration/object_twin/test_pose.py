"""The mount offset's convention, ICP recovering a known offset from exact points, and the ICP's
fitness, RMSE and standard deviations meaning what they say on noisy planes."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.captures import AveragedCapture
from calibration.object_twin.fit import fit_object
from calibration.object_twin.pose import (
    MountModel,
    icp_point_to_plane,
    information_matrix,
    mount_model,
    offset_from_transform,
    pose_std,
    register_mount,
    sample_model,
    transform_from_offset,
)
from sim_core.camera import F_60_24_MHZ
from sim_core.errors import InvalidInputError
from sim_core.geometry import transform_triangles
from sim_core.scene import build_scene
from sim_core.scene_spec import ObjectPose, load_scene_spec
from sim_core.twin_file import MountParameters, ObjectTwinFile, with_object_twin
from tests.sim_core.scenes import EXAMPLES

SPEC = load_scene_spec(EXAMPLES / "satellite_ground_test.yaml")
OFFSET = ObjectPose(position_m=(0.006, -0.004, 0.003), rotation_deg=(1.2, -0.7, 1.6))
#: cameras around and above the mount (exact points on every face, so all 6 DoF are determined)
CAMERAS = np.array([[np.sin(a), -np.cos(a), 0.5] for a in np.radians([0, 90, 180, 270])])


def _real_model() -> MountModel:
    """The mounted objects with OFFSET applied the way a scene applies an object file."""
    twin = with_object_twin(None, ObjectTwinFile(mount=MountParameters(pose_offset=OFFSET)))
    mounted = [o for o in SPEC.objects if o.on_turntable]
    scene = build_scene(SPEC.model_copy(update={"objects": mounted}), EXAMPLES,
                        turntable_deg=0.0, twin=twin)
    nominal = mount_model(SPEC, EXAMPLES)
    return MountModel(scene.triangles_m, scene.normals, scene.object_index, scene.object_names,
                      nominal.axis_point_m)


def test_the_offset_matrix_is_what_the_scene_applies():
    nominal = mount_model(SPEC, EXAMPLES)
    moved = transform_triangles(nominal.triangles_m,
                                transform_from_offset(OFFSET, nominal.axis_point_m))
    np.testing.assert_allclose(moved, _real_model().triangles_m, atol=1e-12)
    back = offset_from_transform(transform_from_offset(OFFSET, nominal.axis_point_m),
                                 nominal.axis_point_m)
    np.testing.assert_allclose(back.position_m, OFFSET.position_m, atol=1e-12)
    np.testing.assert_allclose(back.rotation_deg, OFFSET.rotation_deg, atol=1e-9)


def test_icp_recovers_a_known_offset_from_exact_points():
    points, _, _ = sample_model(_real_model(), CAMERAS, spacing_m=0.003, seed=3)
    reg = register_mount(points, mount_model(SPEC, EXAMPLES), CAMERAS)
    np.testing.assert_allclose(reg.offset.position_m, OFFSET.position_m, atol=1e-4)
    np.testing.assert_allclose(reg.offset.rotation_deg, OFFSET.rotation_deg, atol=0.02)
    assert reg.fitness > 0.95


def test_the_registration_is_the_same_to_the_last_bit_run_to_run():
    points, _, _ = sample_model(_real_model(), CAMERAS, spacing_m=0.004, seed=5)
    noisy = points + np.random.default_rng(1).normal(scale=0.001, size=points.shape)
    model = mount_model(SPEC, EXAMPLES)
    a, b = (register_mount(noisy, model, CAMERAS) for _ in range(2))
    assert np.array_equal(a.transform, b.transform)
    assert (a.fitness, a.inlier_rmse_m, a.std) == (b.fitness, b.inlier_rmse_m, b.std)


def _planes(rng: np.random.Generator, n: int, normals: np.ndarray) -> np.ndarray:
    """``n`` random points on each plane through the origin with one of ``normals``, within
    0.1 m of it."""
    out = []
    for nrm in normals:
        u = np.cross(nrm, [0.3, 0.5, 0.8])
        u /= np.linalg.norm(u)
        v = np.cross(nrm, u)
        a, b = rng.uniform(0.0, 0.1, (2, n))
        out.append(a[:, None] * u + b[:, None] * v + 0.02 * nrm)
    return np.concatenate(out)


CORNER = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def test_fitness_rmse_and_std_mean_what_they_say_on_noisy_planes():
    """Three faces of a box, measured with 1 mm noise along their normals: the RMSE is the
    point-to-plane noise, fitness the share matched, and the standard deviations those of the
    estimates over repeated measurements."""
    rng = np.random.default_rng(7)
    target = _planes(rng, 4000, CORNER)
    target_normals = np.repeat(CORNER, 4000, axis=0)
    sigma, shift = 0.001, np.array([0.003, -0.002, 0.001])
    estimates, stds, rmses = [], [], []
    for _ in range(40):
        clean = _planes(rng, 300, CORNER)
        noisy = clean + rng.normal(scale=sigma, size=(900, 1)) * np.repeat(CORNER, 300, axis=0)
        res = icp_point_to_plane(noisy + shift, target, target_normals)
        info = information_matrix(noisy + shift, target, target_normals, 0.006, res.transform)
        std = pose_std(info, res.inlier_rmse_m)
        assert res.fitness == 1.0  # every point has a sample within 6 mm
        estimates.append(res.transform[:3, 3])
        stds.append(std["translation_m"])
        rmses.append(res.inlier_rmse_m)
    np.testing.assert_allclose(np.mean(estimates, axis=0), -shift, atol=2e-4)
    assert np.median(rmses) == pytest.approx(sigma, rel=0.1)
    # the reported standard deviation is the spread of the estimates (within sampling error)
    np.testing.assert_allclose(np.std(estimates, axis=0), np.median(stds, axis=0), rtol=0.35)


def test_what_vertical_faces_do_not_determine_is_not_moved_and_has_no_std():
    """Two vertical faces say nothing about the height: ICP leaves it, its std is infinite."""
    rng = np.random.default_rng(3)
    walls = CORNER[:2]
    target = _planes(rng, 4000, walls)
    normals = np.repeat(walls, 4000, axis=0)
    source = _planes(rng, 500, walls) + np.array([0.002, 0.003, 0.004])
    res = icp_point_to_plane(source, target, normals)
    np.testing.assert_allclose(res.transform[:3, 3], (-0.002, -0.003, 0.0), atol=2e-4)
    std = pose_std(information_matrix(source, target, normals, 0.006, res.transform),
                   res.inlier_rmse_m)
    assert np.isinf(std["translation_m"][2])
    assert np.isfinite(std["translation_m"][:2]).all()


def test_a_cloud_that_does_not_overlap_the_mesh_is_refused_without_a_pose():
    points, _, _ = sample_model(_real_model(), CAMERAS, spacing_m=0.003, seed=3)
    with pytest.raises(InvalidInputError) as exc:
        register_mount(np.add(points, (0.4, 0.0, 0.0)), mount_model(SPEC, EXAMPLES), CAMERAS)
    assert exc.value.field == "mesh"
    assert "does not overlap" in str(exc.value)


def test_a_different_object_at_the_same_place_is_refused():
    """A sphere where the satellite should be: points near the model, but no fit."""
    sphere = np.random.default_rng(0).standard_normal((4000, 3))
    sphere = 0.07 * sphere / np.linalg.norm(sphere, axis=1, keepdims=True) + [0.0, 0.0, 0.14]
    with pytest.raises(InvalidInputError) as exc:
        register_mount(sphere, mount_model(SPEC, EXAMPLES), CAMERAS)
    assert exc.value.field == "mesh"


def _dark_capture(angle_deg: float) -> AveragedCapture:
    shape = (171, 224)
    return AveragedCapture(
        turntable_angle_deg=angle_deg, solar_suns=0.0, shutter_open=False, n_frames=8,
        phase_images=np.zeros((1, 4, *shape)), intensity=np.full(shape, 100.0),
        intensity_std=np.ones(shape), amplitude=np.full(shape, 2.0),
        phase_rad=np.zeros((1, *shape)), valid=np.zeros(shape, dtype=bool),
        frequencies_hz=np.array([F_60_24_MHZ]), exposure_s=500e-6)


def test_frames_with_too_few_valid_pixels_are_refused():
    with pytest.raises(InvalidInputError) as exc:
        fit_object(SPEC, EXAMPLES, None, [_dark_capture(0.0)])
    assert exc.value.field == "captures[0]"
    assert "valid pixels" in str(exc.value)
    with pytest.raises(InvalidInputError) as exc:
        fit_object(SPEC, EXAMPLES, None, [])
    assert exc.value.field == "captures"


def test_views_too_dark_to_fit_are_named_and_all_dark_views_are_refused():
    from calibration.object_twin.fit import _dark_views

    dark = _dark_views([_dark_capture(-30.0), _dark_capture(45.0)], 300, 10.0)
    assert [d["turntable_angle_deg"] for d in dark] == [-30.0, 45.0]
    assert "0 valid pixels" in dark[1]["reason"] and dark[1]["reason"].endswith("left out")
    # fewer than two views left: the fit is refused, naming the first dark view
    with pytest.raises(InvalidInputError) as exc:
        fit_object(SPEC, EXAMPLES, None, [_dark_capture(a) for a in (-30.0, 0.0, 30.0)])
    assert exc.value.field == "captures[0]"
