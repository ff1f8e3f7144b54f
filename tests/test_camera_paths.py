"""Camera paths: exact orbits, smooth bounded random motion, viewpoint pools, and the JSON files."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from volsr_core.errors import InputError
from volsr_core.scene.camera import Camera
from volsr_core.scene.camera_paths import (candidate_pool, orbit, random_start, read_camera_path,
                                           smooth_random_path, write_camera_path)

BOUNDS = (-95.25, 95.25, -80.0, 80.0, -120.0, 110.0)
CORNERS = np.array([[x, y, z] for x in BOUNDS[:2] for y in BOUNDS[2:4] for z in BOUNDS[4:]])


def start_camera() -> Camera:
    return Camera.framing(BOUNDS, direction=(0.3, 1.0, -0.2), view_up=(0.1, 0.0, 1.0)).roll(5.0)


def offsets(cameras: list[Camera]) -> np.ndarray:
    return np.array([c.position - c.focal_point for c in cameras])


def directions(cameras: list[Camera]) -> np.ndarray:
    return np.array([c.direction_of_projection for c in cameras])


def angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def encloses_bounds(camera: Camera) -> bool:
    depth = (CORNERS - camera.position) @ camera.direction_of_projection
    near, far = camera.clipping_range
    return near <= depth.min() and depth.max() <= far


# orbit ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("elevation", [0.0, 25.0, -40.0])
def test_orbit_steps_are_exact_turns_at_constant_distance_and_elevation(elevation):
    start = start_camera()
    cameras = orbit(start, 12, elevation=elevation)
    assert len(cameras) == 12
    axis = start.view_up
    v = offsets(cameras)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), start.distance, rtol=1e-12)
    np.testing.assert_allclose(np.degrees(np.arcsin(v @ axis / start.distance)), elevation, atol=1e-9)
    flat = v - np.outer(v @ axis, axis)
    turn = np.degrees(np.arctan2(np.cross(flat[:-1], flat[1:]) @ axis, np.sum(flat[:-1] * flat[1:], axis=1)))
    np.testing.assert_allclose(turn, 30.0, atol=1e-9)
    for c in cameras:
        np.testing.assert_array_equal(c.focal_point, start.focal_point)
        assert c.view_angle == start.view_angle and c.clipping_range == start.clipping_range


def test_orbit_frame_zero_is_the_elevated_start_and_azimuth_without_elevation():
    start = start_camera()
    first = orbit(start, 7, elevation=15.0)[0]
    np.testing.assert_allclose(first.position, start.elevation(15.0).position, atol=1e-9)
    np.testing.assert_allclose(first.view_up, start.elevation(15.0).view_up, atol=1e-12)
    for i, c in enumerate(orbit(start, 5, degrees=90.0)):
        np.testing.assert_allclose(c.position, start.azimuth(18.0 * i).position, atol=1e-9)
        np.testing.assert_allclose(c.view_up, start.azimuth(18.0 * i).view_up, atol=1e-12)


@pytest.mark.parametrize("elevation", [0.0, 30.0])
def test_full_orbit_closes_without_repeating_the_start(elevation):
    start = start_camera()
    cameras = orbit(start, 8, elevation=elevation)
    one_more = orbit(start, 9, degrees=360.0 * 9 / 8, elevation=elevation)
    np.testing.assert_allclose(one_more[-1].position, cameras[0].position, atol=1e-9)
    np.testing.assert_allclose(one_more[-1].view_up, cameras[0].view_up, atol=1e-12)
    gaps = np.linalg.norm(np.diff(offsets(cameras + cameras[:1]), axis=0), axis=1)
    np.testing.assert_allclose(gaps, gaps[0], rtol=1e-9)  # the last frame is one step before the first


def test_orbit_rejects_no_frames():
    with pytest.raises(ValueError):
        orbit(start_camera(), 0)


# smooth random path -----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def path() -> list[Camera]:
    return smooth_random_path(start_camera(), 400, np.random.default_rng(2024), bounds=BOUNDS)


def test_smooth_path_starts_at_start(path):
    start = start_camera()
    np.testing.assert_allclose(path[0].position, start.position, atol=1e-9)
    np.testing.assert_allclose(path[0].view_up, start.view_up, atol=1e-12)
    assert path[0].view_angle == start.view_angle


def test_smooth_path_has_no_jumps(path):
    d = directions(path)
    step = angles_deg(d[1:], d[:-1])
    assert step.max() <= 3.0 + 1.5 + 1e-9
    assert step.mean() > 0.3, "the camera does move"
    zoom = np.log(np.array([c.view_angle for c in path]))
    assert np.abs(np.diff(zoom)).max() <= math.log1p(0.01) + 1e-12


def test_smooth_path_is_smooth(path):
    v = offsets(path) / start_camera().distance
    second = np.linalg.norm(v[2:] - 2.0 * v[1:-1] + v[:-2], axis=1)
    assert second.max() < 0.01  # radians per frame^2: velocity changes gradually
    angle = np.array([c.view_angle for c in path])
    assert np.abs(angle[2:] - 2.0 * angle[1:-1] + angle[:-2]).max() < 0.05


def test_smooth_path_stays_within_its_ranges(path):
    start = start_camera()
    v = offsets(path)
    elevation = np.degrees(np.arcsin(v @ start.view_up / np.linalg.norm(v, axis=1)))
    assert np.abs(elevation).max() <= 60.0 + 1e-9
    zoom = start.view_angle / np.array([c.view_angle for c in path])
    assert zoom.min() >= 0.8 - 1e-12 and zoom.max() <= 1.5 + 1e-12
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), start.distance, rtol=1e-9)


def test_smooth_path_is_never_degenerate_and_keeps_the_bounds_clipped(path):
    start = start_camera()
    for c in path:
        assert abs(float(c.view_up @ c.direction_of_projection)) < 1e-9
        assert float(c.view_up @ start.view_up) > 0.45, "never upside down (elevation <= 60 degrees)"
        assert encloses_bounds(c)


def test_smooth_path_is_deterministic_per_seed():
    start = start_camera()
    a = smooth_random_path(start, 90, np.random.default_rng(7))
    b = smooth_random_path(start, 90, np.random.default_rng(7))
    c = smooth_random_path(start, 90, np.random.default_rng(8))
    assert [x.to_dict() for x in a] == [x.to_dict() for x in b]
    assert [x.to_dict() for x in a] != [x.to_dict() for x in c]


def test_smooth_path_works_for_parallel_cameras_and_rejects_bad_ranges():
    start = Camera.framing(BOUNDS, parallel_projection=True)
    cameras = smooth_random_path(start, 50, np.random.default_rng(1), zoom_range=(0.5, 2.0))
    scale = np.array([c.parallel_scale for c in cameras])
    assert scale.min() >= start.parallel_scale / 2.0 - 1e-9 and scale.max() <= start.parallel_scale * 2.0 + 1e-9
    with pytest.raises(ValueError):
        smooth_random_path(start, 10, np.random.default_rng(1), zoom_range=(1.2, 1.5))
    with pytest.raises(ValueError):
        smooth_random_path(start, 10, np.random.default_rng(1), max_elevation=90.0)


# candidate pool ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def pool() -> list[Camera]:
    return candidate_pool(BOUNDS, 300, np.random.default_rng(99))


def test_pool_covers_the_sphere(pool):
    b = np.asarray(BOUNDS).reshape(3, 2)
    centre = b.mean(axis=1)
    seen_from = np.array([c.position - centre for c in pool])
    seen_from /= np.linalg.norm(seen_from, axis=1, keepdims=True)
    probes = np.random.default_rng(0).normal(size=(2000, 3))
    probes /= np.linalg.norm(probes, axis=1, keepdims=True)
    nearest = np.degrees(np.arccos(np.clip(probes @ seen_from.T, -1, 1).max(axis=1)))
    assert nearest.max() < 12.0, "every direction has a camera within 12 degrees"
    assert np.linalg.norm(seen_from.mean(axis=0)) < 0.05, "no side is favoured"


def test_pool_cameras_look_at_the_centre_from_the_right_distance(pool):
    b = np.asarray(BOUNDS).reshape(3, 2)
    centre, radius = b.mean(axis=1), 0.5 * np.linalg.norm(b[:, 1] - b[:, 0])
    framing = radius / math.sin(math.radians(15.0))
    for c in pool:
        assert np.abs(c.focal_point - centre).max() <= 0.05 * radius + 1e-9
        assert 0.9 * framing - 1e-9 <= c.distance <= 1.6 * framing + 1e-9
        assert c.view_angle == 30.0 and not c.parallel_projection
        assert c.parallel_scale == pytest.approx(radius * c.distance / framing)
        assert abs(float(c.view_up @ c.direction_of_projection)) < 1e-9
        assert encloses_bounds(c)


def test_pool_rolls_are_limited(pool):
    rolls = []
    for c in pool:
        d = c.direction_of_projection
        reference = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([0.0, -1.0, 0.0])
        upright = reference - (reference @ d) * d
        rolls.append(angles_deg(c.view_up, upright / np.linalg.norm(upright)))
    assert max(rolls) <= 20.0 + 1e-6
    assert max(rolls) > 10.0, "rolls do vary"


def test_pool_and_random_start_are_deterministic():
    a = candidate_pool(BOUNDS, 20, np.random.default_rng(3))
    b = candidate_pool(BOUNDS, 20, np.random.default_rng(3))
    assert [c.to_dict() for c in a] == [c.to_dict() for c in b]
    picks = {id(random_start(a, np.random.default_rng(s))) for s in range(30)}
    assert len(picks) > 5
    assert random_start(a, np.random.default_rng(4)) is random_start(a, np.random.default_rng(4))
    with pytest.raises(ValueError):
        random_start([], np.random.default_rng(0))


# files ------------------------------------------------------------------------------------------
def test_json_round_trip_is_exact(tmp_path, path):
    cameras = path[:25] + [Camera.framing(BOUNDS, parallel_projection=True).roll(33.0)]
    target = tmp_path / "path.json"
    write_camera_path(target, cameras)
    doc = json.loads(target.read_text(encoding="utf-8"))
    assert doc["format"] == "volsr-camera-path" and doc["version"] == 1 and len(doc["cameras"]) == 26
    assert set(doc["cameras"][0]) == {"position", "focal_point", "view_up", "view_angle", "parallel_projection",
                                      "parallel_scale", "clipping_range"}
    again = read_camera_path(target)
    assert [c.to_dict() for c in again] == [c.to_dict() for c in cameras]
    for a, b in zip(again, cameras):
        np.testing.assert_array_equal(a.view_matrix(), b.view_matrix())
    assert [p.name for p in tmp_path.iterdir()] == ["path.json"], "no temporary file left behind"


def test_write_replaces_an_existing_file_and_refuses_an_empty_path(tmp_path):
    target = tmp_path / "path.json"
    write_camera_path(target, orbit(start_camera(), 4))
    write_camera_path(target, orbit(start_camera(), 2))
    assert len(read_camera_path(target)) == 2
    with pytest.raises(ValueError):
        write_camera_path(target, [])
    assert len(read_camera_path(target)) == 2


def test_a_bare_list_of_cameras_is_read(tmp_path):
    target = tmp_path / "bare.json"
    target.write_text(json.dumps([{"position": [0, -100, 0], "focal_point": [0, 0, 0], "view_up": [0, 0, 1]},
                                  start_camera().to_dict()]))
    cameras = read_camera_path(target)
    assert len(cameras) == 2 and cameras[0].view_angle == 30.0
    assert cameras[1].to_dict() == start_camera().to_dict()


GOOD = {"position": [0, -100, 0], "focal_point": [0, 0, 0], "view_up": [0, 0, 1]}
BAD_FILES = {
    "not JSON": ("{'cameras': oops", "not valid JSON"),
    "empty file": ("", "not valid JSON"),
    "a number": ("42", "expected a JSON object or list"),
    "no format": (json.dumps({"cameras": [GOOD]}), "not a camera-path file"),
    "other format": (json.dumps({"format": "something-else", "version": 1, "cameras": [GOOD]}), "not a camera-path"),
    "newer version": (json.dumps({"format": "volsr-camera-path", "version": 2, "cameras": [GOOD]}), "version 2"),
    "cameras not a list": (json.dumps({"format": "volsr-camera-path", "version": 1, "cameras": GOOD}), "'cameras'"),
    "empty list": ("[]", "contains no cameras"),
    "empty cameras": (json.dumps({"format": "volsr-camera-path", "version": 1, "cameras": []}), "contains no cameras"),
    "camera not an object": (json.dumps([GOOD, [1, 2, 3]]), "camera 1: expected an object"),
    "camera lacks position": (json.dumps([GOOD, {"focal_point": [0, 0, 0]}]), "camera 1: camera lacks 'position'"),
    "zero-length view": (json.dumps([GOOD, GOOD, {"position": [1, 2, 3], "focal_point": [1, 2, 3]}]),
                         "camera 2: camera position and focal point coincide"),
    "view up along the view": (json.dumps([{**GOOD, "view_up": [0, 1, 0]}]), "camera 0: view_up is parallel"),
    "short vector": (json.dumps([{**GOOD, "position": [0, 1]}]), "camera 0:"),
    "unknown key": (json.dumps([{**GOOD, "zoom": 2}]), "camera 0: unknown camera keys: zoom"),
    "bad clipping range": (json.dumps([{**GOOD, "clipping_range": [5, 1]}]), "camera 0: clipping range"),
    "wrong value type": (json.dumps([{**GOOD, "view_angle": "wide"}]), "camera 0:"),
}


@pytest.mark.parametrize("case", BAD_FILES)
def test_bad_files_raise_one_line_input_errors_naming_the_file(tmp_path, case):
    text, expected = BAD_FILES[case]
    target = tmp_path / "bad.json"
    target.write_text(text, encoding="utf-8")
    with pytest.raises(InputError) as info:
        read_camera_path(target)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{target}: ")
    assert expected in message


@pytest.mark.parametrize("kind", ["missing", "folder", "binary"])
def test_unreadable_files_raise_input_errors(tmp_path, kind):
    target = tmp_path / "path.json"
    if kind == "folder":
        target.mkdir()
    elif kind == "binary":
        target.write_bytes(b"\xff\xfe\x00\x81garbage")
    with pytest.raises(InputError) as info:
        read_camera_path(target)
    assert str(info.value).startswith(f"{target}: ") and "\n" not in str(info.value)
