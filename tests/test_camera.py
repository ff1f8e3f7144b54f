"""Our Camera against VTK's own vtkCamera / vtkRenderer math (no rendering, no display needed)."""
from __future__ import annotations

import numpy as np
import pytest

from volsr_core.scene.camera import Camera, rotation_between

pytestmark = pytest.mark.vtk
vtk_core = pytest.importorskip("vtkmodules.vtkRenderingCore")
vtk_gl = pytest.importorskip("vtkmodules.vtkRenderingOpenGL2")

from volsr_core.scene.vtk_bridge import apply_camera  # noqa: E402

BOUNDS = (-50.0, 70.0, -30.0, 40.0, -100.0, 90.0)

CAMERAS = {
    "perspective": Camera(position=[10, -200, 30], focal_point=[1, 2, 3], view_up=[0.3, 0.1, 1],
                          view_angle=30, clipping_range=(50, 400)),
    "parallel": Camera(position=[-120, 40, 260], focal_point=[5, -7, 11], view_up=[1, 0.2, -0.3],
                       view_angle=45, parallel_projection=True, parallel_scale=37.5, clipping_range=(20, 600)),
    "narrow, looking down the body axis": Camera(position=[3, 4, 500], focal_point=[0, 0, 0], view_up=[0.01, -1, 0.2],
                                                 view_angle=12, clipping_range=(300, 700)),
    "wide, behind and below": Camera(position=[80, 300, -150], focal_point=[-10, 20, 5], view_up=[-0.5, 0.4, 0.77],
                                     view_angle=70, clipping_range=(1, 1000)),
}
ASPECTS = (1.0, 1.7, 0.6)
SIZES = ((300, 200), (200, 300), (256, 256))


def to_vtk(camera: Camera):
    """A vtkCamera set up like ``camera``."""
    c = vtk_core.vtkCamera()
    apply_camera(c, camera)
    return c


def matrix(m) -> np.ndarray:
    return np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)])


def renderer(width: int, height: int):
    """A vtkRenderer in a never-rendered window of the given size (for its coordinate math)."""
    window = vtk_gl.vtkGenericOpenGLRenderWindow()
    window.SetSize(width, height)
    ren = vtk_core.vtkRenderer()
    window.AddRenderer(ren)
    ren._window = window  # keep the window alive as long as the renderer
    return ren


def assert_same_camera(ours: Camera, theirs, atol: float = 1e-9) -> None:
    scale = max(1.0, float(np.abs(ours.position).max()))
    np.testing.assert_allclose(ours.position, theirs.GetPosition(), atol=atol * scale)
    np.testing.assert_allclose(ours.focal_point, theirs.GetFocalPoint(), atol=atol * scale)
    np.testing.assert_allclose(ours.view_up, theirs.GetViewUp(), atol=atol)
    assert ours.view_angle == pytest.approx(theirs.GetViewAngle(), rel=1e-12)
    assert ours.parallel_scale == pytest.approx(theirs.GetParallelScale(), rel=1e-12)


@pytest.mark.parametrize("name", CAMERAS)
def test_view_matrix_matches_vtk(name):
    camera = CAMERAS[name]
    np.testing.assert_allclose(camera.view_matrix(), matrix(to_vtk(camera).GetViewTransformMatrix()), atol=1e-9)


@pytest.mark.parametrize("aspect", ASPECTS)
@pytest.mark.parametrize("name", CAMERAS)
def test_projection_matrix_matches_vtk(name, aspect):
    camera = CAMERAS[name]
    theirs = matrix(to_vtk(camera).GetProjectionTransformMatrix(aspect, -1, 1))
    np.testing.assert_allclose(camera.projection_matrix(aspect), theirs, rtol=1e-12, atol=1e-12)


MOTIONS = [("azimuth", 37.0), ("azimuth", -150.0), ("elevation", -23.0), ("elevation", 61.0), ("roll", 71.0),
           ("roll", -200.0), ("zoom", 1.8), ("zoom", 0.7), ("dolly", 1.6), ("dolly", 0.5)]


@pytest.mark.parametrize("motion, amount", MOTIONS)
@pytest.mark.parametrize("name", CAMERAS)
def test_motions_match_vtk(name, motion, amount):
    camera = CAMERAS[name]
    theirs = to_vtk(camera)
    getattr(theirs, motion.capitalize())(amount)
    # vtkCamera.Elevation leaves the view up alone (it is no longer orthogonal); ours carries it
    # along the rotation. After VTK's OrthogonalizeViewUp both agree for |elevation| < 90 degrees.
    theirs.OrthogonalizeViewUp()
    assert_same_camera(getattr(camera, motion)(amount), theirs)


@pytest.mark.parametrize("motion, amount", [m for m in MOTIONS if m[0] in ("azimuth", "elevation", "roll")])
@pytest.mark.parametrize("name", CAMERAS)
def test_rotation_between_is_the_angle_a_camera_motion_turns(name, motion, amount):
    camera = CAMERAS[name]
    expected = abs((amount + 180.0) % 360.0 - 180.0)  # a turn by ``amount`` degrees about one axis
    assert rotation_between(camera, getattr(camera, motion)(amount)) == pytest.approx(expected, abs=1e-6)
    assert rotation_between(camera, camera.zoom(1.5)) == pytest.approx(0.0, abs=1e-6)


def test_motion_chain_matches_vtk():
    camera = CAMERAS["perspective"]
    theirs = to_vtk(camera)
    ours = camera
    for motion, amount in MOTIONS:
        getattr(theirs, motion.capitalize())(amount)
        theirs.OrthogonalizeViewUp()
        ours = getattr(ours, motion)(amount)
    assert_same_camera(ours, theirs)


@pytest.mark.parametrize("parallel", [False, True])
@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("direction", [(0.0, 1.0, 0.0), (0.3, 1.0, -0.4), (-1.0, 0.2, 0.5)])
def test_framing_matches_reset_camera(direction, size, parallel):
    ren = renderer(*size)
    theirs = ren.GetActiveCamera()
    d = np.asarray(direction) / np.linalg.norm(direction)
    theirs.SetFocalPoint(0.0, 0.0, 0.0)
    theirs.SetPosition(*-d)
    theirs.SetViewUp(0.0, 0.0, 1.0)
    theirs.SetParallelProjection(parallel)
    ren.ResetCamera(*BOUNDS)
    # vtkRenderer.ResetCamera fits the bounding sphere of the box and forces the view angle to 30
    ours = Camera.framing(BOUNDS, direction=direction, view_up=(0, 0, 1), view_angle=30.0,
                          parallel_projection=parallel, aspect=size[0] / size[1])
    assert theirs.GetViewAngle() == 30.0
    theirs.OrthogonalizeViewUp()  # VTK keeps the view up it was given; ours is always orthogonalised
    np.testing.assert_allclose(ours.position, theirs.GetPosition(), atol=1e-9)
    np.testing.assert_allclose(ours.focal_point, theirs.GetFocalPoint(), atol=1e-9)
    np.testing.assert_allclose(ours.view_up, theirs.GetViewUp(), atol=1e-12)
    assert ours.parallel_scale == pytest.approx(theirs.GetParallelScale(), rel=1e-12)


def box_depths(camera: Camera, bounds) -> tuple[float, float]:
    b = np.asarray(bounds).reshape(3, 2)
    corners = np.array([[x, y, z] for x in b[0] for y in b[1] for z in b[2]])
    depth = (corners - camera.position) @ camera.direction_of_projection
    return float(depth.min()), float(depth.max())


@pytest.mark.parametrize("name", CAMERAS)
def test_reset_clipping_range_agrees_with_vtk(name):
    camera = CAMERAS[name].dolly(0.3)  # stand well outside BOUNDS
    ren = renderer(300, 200)
    ren.SetActiveCamera(to_vtk(camera))
    ren.ResetCameraClippingRange(*BOUNDS)
    vtk_near, vtk_far = ren.GetActiveCamera().GetClippingRange()
    near, far = camera.reset_clipping_range(BOUNDS).clipping_range
    nearest, farthest = box_depths(camera, BOUNDS)
    # Both enclose the box's depth range, ours with 1% of slack. VTK adds more breathing room:
    # near = 0.99 * nearest - 0.5 * span, far = 1.01 * farthest + 0.5 * span (ClippingRangeExpansion
    # 0.5, span measured after the near change), near >= NearClippingPlaneTolerance * far. So ours
    # lies inside VTK's range, and both enclose the box.
    assert vtk_near <= near <= nearest
    assert farthest <= far <= vtk_far
    span = farthest - nearest
    assert nearest - near <= 0.011 * span and far - farthest <= 0.011 * span


@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("name", CAMERAS)
def test_world_to_pixel_matches_world_to_display(name, size):
    camera = CAMERAS[name]
    width, height = size
    ren = renderer(width, height)
    ren.SetActiveCamera(to_vtk(camera))
    rng = np.random.default_rng(5)
    right, up, forward = camera.basis()
    points = (camera.focal_point + rng.uniform(-20, 20, (25, 1)) * right + rng.uniform(-20, 20, (25, 1)) * up
              + rng.uniform(-30, 30, (25, 1)) * forward)
    ours = camera.world_to_pixel(points, width, height)
    for point, (x, y) in zip(points, ours):
        ren.SetWorldPoint(*point, 1.0)
        ren.WorldToDisplay()
        x_vtk, y_vtk, _ = ren.GetDisplayPoint()
        # VTK's display y runs bottom-up from the window's bottom edge; ours top-down from the top edge
        assert x == pytest.approx(x_vtk, abs=1e-7)
        assert y == pytest.approx(height - y_vtk, abs=1e-7)


@pytest.mark.parametrize("name", CAMERAS)
def test_points_on_a_ray_project_back_to_its_pixel(name):
    camera = CAMERAS[name]
    width, height = 97, 61
    rng = np.random.default_rng(11)
    for px, py in zip(rng.uniform(0, width, 20), rng.uniform(0, height, 20)):
        origin, direction = camera.ray(px, py, width, height)
        assert np.linalg.norm(direction) == pytest.approx(1.0)
        points = origin + np.outer([0.5, 1.0, 1.7], camera.distance * direction)
        np.testing.assert_allclose(camera.world_to_pixel(points, width, height), [[px, py]] * 3, atol=1e-8)


def test_pixel_centre_of_the_image_looks_at_the_focal_point():
    camera = CAMERAS["perspective"]
    origin, direction = camera.ray(50.0, 30.0, 100, 60)
    np.testing.assert_allclose(direction, camera.direction_of_projection, atol=1e-12)
    np.testing.assert_allclose(camera.world_to_pixel(camera.focal_point, 100, 60), [50.0, 30.0], atol=1e-9)


def test_dict_round_trip_is_exact_and_orthogonalises_once():
    camera = CAMERAS["wide, behind and below"].azimuth(13.0).elevation(7.0).roll(3.0)
    again = Camera.from_dict(camera.to_dict())
    assert again.to_dict() == camera.to_dict()
    assert abs(float(camera.view_up @ camera.direction_of_projection)) < 1e-12
    assert np.linalg.norm(camera.view_up) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("name", CAMERAS)
def test_pixel_size_at_focus_is_what_a_step_on_the_focal_plane_projects_to(name):
    camera = CAMERAS[name]
    right, up, _ = camera.basis()
    width, height = 300, 200
    size = camera.pixel_size_at_focus(height)
    for axis in (right, up):
        step = camera.world_to_pixel(np.stack([camera.focal_point, camera.focal_point + size * axis]), width, height)
        assert np.linalg.norm(step[1] - step[0]) == pytest.approx(1.0, rel=1e-9)
