"""The depth sensor families of the simulator (hmocap_sim.depth_sensor): quantisation and
noise by distance, holes at depth edges and on dark or grazing surfaces, determinism."""

import dataclasses

import numpy as np
import pytest

from hmocap_sim.depth_sensor import (
    SENSORS,
    fatten_edges,
    incidence_cosine,
    sensor_by_name,
    sensor_depth,
)
from hmocap_sim.render.depth import depth_to_millimetres

FX = 575.0
SHAPE = (120, 160)


def _wall(z: float) -> np.ndarray:
    return np.full(SHAPE, z, np.float32)


def _box_before_wall(z_box: float = 1.5, z_wall: float = 3.0) -> np.ndarray:
    z = _wall(z_wall)
    z[40:80, 60:100] = z_box
    return z


def test_depth_steps_grow_as_the_square_of_the_distance():
    """Without noise the depths a wall can read are the disparity steps ``z^2 step / (f b)``."""
    sensor = dataclasses.replace(SENSORS["structured_light"], disparity_sigma_px=0.0, dropout=0.0)
    fb = sensor.native_fx * sensor.baseline_m
    for z in (1.0, 2.0, 3.0):
        # walls spread over a few steps: the distinct values read are consecutive disparity levels
        zs = np.linspace(z, z + 4 * sensor.depth_step(z), SHAPE[0] * SHAPE[1]).reshape(SHAPE)
        mm = sensor_depth(zs, np.random.default_rng(0), FX, sensor)
        levels = np.unique(mm[mm > 0]) / 1000.0
        steps = np.diff(levels)
        assert steps.mean() == pytest.approx(sensor.depth_step(z), rel=0.1, abs=0.0015)
        # each level is fb / (k * step) for an integer k, rounded to the millimetre
        k = np.rint(fb / levels / sensor.disparity_step_px)
        assert np.all(np.abs(levels - fb / (k * sensor.disparity_step_px)) <= 0.0005 + 1e-9)
    assert sensor.depth_step(3.0) == pytest.approx(9 * sensor.depth_step(1.0))


@pytest.mark.parametrize("name", ["structured_light", "stereo"])
def test_noise_grows_as_the_square_of_the_distance(name):
    sensor = dataclasses.replace(SENSORS[name], disparity_step_px=0.0, dropout=0.0)
    for z in (1.0, 3.0):
        mm = sensor_depth(_wall(z), np.random.default_rng(1), FX, sensor)
        err = mm[mm > 0] / 1000.0 - z
        assert np.std(err) == pytest.approx(sensor.depth_sigma(z), rel=0.15, abs=0.001)


@pytest.mark.parametrize("name", ["structured_light", "stereo"])
def test_holes_at_depth_edges_not_on_a_flat_wall(name):
    sensor = SENSORS[name]
    wall = sensor_depth(_wall(2.0), np.random.default_rng(2), FX, sensor)
    assert np.mean(wall == 0) < 0.01  # only the random dropout
    zbuf = _box_before_wall()
    mm = sensor_depth(zbuf, np.random.default_rng(2), FX, sensor)
    # the band left of the box that the projector / second imager does not see: f b (1/z1 - 1/z2)
    band = int(FX * sensor.baseline_m * (1 / 1.5 - 1 / 3.0))
    fattened = int(round(sensor.fattening_px * FX / sensor.native_fx))  # the box spreads over them
    left = mm[45:75, 60 - band + 1:60 - fattened]
    right = mm[45:75, 100 + fattened + 1:100 + band]
    assert np.mean(left == 0) > 0.9
    assert np.mean(right == 0) < 0.05
    # the box's rims are holed or fattened, its inside is measured
    assert np.mean(mm[50:70, 70:90] == 0) < 0.01


def test_edge_fattening_spreads_the_nearer_surface():
    zbuf = _box_before_wall()
    fat, took = fatten_edges(zbuf, 2.0, 0.05)
    assert took[60, 100:102].all() and not took[60, 103:].any()  # two pixels into the wall
    assert np.all(fat[60, 100:102] == pytest.approx(1.5))
    assert not took[60, 60:100].any()  # the box itself keeps its depth


def test_dark_and_grazing_surfaces_read_nothing():
    sensor = SENSORS["structured_light"]
    dark = sensor_depth(_wall(2.0), np.random.default_rng(3), FX, sensor, albedo=0.03)
    light = sensor_depth(_wall(2.0), np.random.default_rng(3), FX, sensor, albedo=0.5)
    assert np.mean(dark == 0) > 0.7 and np.mean(light == 0) < 0.01
    # a plane turned 80 degrees from the optical axis about the x axis, 2 m away at the centre
    normal = np.array([0.0, -np.sin(np.deg2rad(80)), np.cos(np.deg2rad(80))])
    v, u = np.mgrid[0:SHAPE[0], 0:SHAPE[1]].astype(np.float64)
    rays = np.stack([(u - 80) / FX, (v - 60) / FX, np.ones(SHAPE)], -1)
    facing = rays @ normal
    plane = (2.0 * normal[2] / facing).astype(np.float32)
    cos = incidence_cosine(plane, FX, 80, 60)
    expected = np.abs(facing) / np.linalg.norm(rays, axis=-1)
    assert np.allclose(cos[1:-1, 1:-1], expected[1:-1, 1:-1], atol=0.01)
    mm = sensor_depth(plane, np.random.default_rng(3), FX, sensor)
    assert np.mean(mm[20:60] == 0) > 0.3  # albedo 0.5 x cos 0.17-0.2 under min_return 0.15 x u


@pytest.mark.parametrize("name", ["structured_light", "stereo"])
def test_same_seed_same_image(name):
    zbuf = _box_before_wall()
    a = sensor_depth(zbuf, np.random.default_rng(4), FX, SENSORS[name])
    b = sensor_depth(zbuf, np.random.default_rng(4), FX, SENSORS[name])
    c = sensor_depth(zbuf, np.random.default_rng(5), FX, SENSORS[name])
    assert a.dtype == np.uint16 and np.array_equal(a, b) and not np.array_equal(a, c)


def test_ideal_sensor_returns_the_z_buffer_in_millimetres():
    zbuf = _box_before_wall()
    zbuf[0, 0] = np.inf
    mm = sensor_depth(zbuf, np.random.default_rng(6), FX, SENSORS["ideal"])
    assert np.array_equal(mm, depth_to_millimetres(zbuf))
    assert mm[0, 0] == 0 and mm[60, 80] == 1500


def test_unknown_sensor_is_refused():
    with pytest.raises(ValueError, match="structured_light"):
        sensor_by_name("tof")


def test_render_depth_takes_each_meshs_albedo():
    """A dark box before a light wall (``depth_scene.render_depth`` with an albedo per mesh):
    the box reads mostly nothing, the wall and the ideal sensor everything."""
    from hmocap_sim.depth_scene import box, depth_camera, render_depth
    from hmocap_sim.render import grid_quad

    cam = depth_camera((0.0, 1.2, 0.0), (0.0, 1.2, 5.0), 320, 240)
    wall = grid_quad((-3.0, -1.8, 3.0), (6.0, 0, 0), (0, 6.0, 0), 8, 8)
    dark = box((0.0, 1.2, 2.0), (0.6, 0.6, 0.1))
    meshes = [wall, dark]
    r = render_depth(cam, meshes, np.random.default_rng(7), "structured_light", albedo=[0.5, 0.02])
    on_box = r.face_id >= r.face_offsets[1]
    on_wall = (r.face_id >= 0) & ~on_box
    assert np.mean(r.depth_mm[on_box] == 0) > 0.8
    assert np.mean(r.depth_mm[on_wall] == 0) < 0.1  # the box's shadow band and edges only
    ideal = render_depth(cam, meshes, np.random.default_rng(7), None, albedo=[0.5, 0.02])
    assert np.all(ideal.depth_mm[r.face_id >= 0] > 0)


def test_the_plain_family_is_the_plain_kinect_model():
    """``structured_light_plain`` measures exactly what :func:`hmocap_sim.render.kinect_depth`
    does with the Kinect v1 parameters, the disparity steps of a 640-pixel sensor kept at any
    width (the depth the shipped gesture forest was trained on)."""
    from hmocap_sim.depth_sensor import sensor_by_name, sensor_depth
    from hmocap_sim.render import KinectNoise, kinect_depth

    z = np.full((240, 320), 2.0)
    z[60:180, 100:200] = 1.3
    z[:, :20] = np.inf
    expected = kinect_depth(z, np.random.default_rng(5), 287.5,
                            dataclasses.replace(KinectNoise(), disparity_step_px=0.0625))
    got = sensor_depth(z, np.random.default_rng(5), 287.5, sensor_by_name("structured_light_plain"))
    assert np.array_equal(got, expected)
