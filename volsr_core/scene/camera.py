"""A camera defined like vtkCamera, in world mm (LPS), and its view/projection matrices.

Image conventions (docs/conventions.md): pixel (0, 0) is the top-left pixel; continuous pixel
coordinates run from 0 at the image's left/top edge, so pixel (x, y) has its centre at
(x + 0.5, y + 0.5). A jitter offset (jx, jy) in pixels moves the ray of every pixel to
(x + 0.5 + jx, y + 0.5 + jy). Matrices follow VTK/OpenGL: camera coordinates have x right,
y up and the camera looking down -z; NDC lie in [-1, 1]^3 with +y up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np

Bounds = Sequence[float]  # (xmin, xmax, ymin, ymax, zmin, zmax), mm


def _vec(v: Any) -> np.ndarray:
    out = np.asarray(v, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(out)):
        raise ValueError(f"camera vector must be finite, got {v}")
    return out


def _rotation(axis: np.ndarray, degrees: float) -> np.ndarray:
    """3x3 right-handed rotation about ``axis`` by ``degrees``."""
    a = axis / np.linalg.norm(axis)
    t = math.radians(degrees)
    c, s = math.cos(t), math.sin(t)
    x, y, z = a
    return np.array([
        [c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
        [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
        [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)],
    ])


@dataclass
class Camera:
    """Perspective or parallel camera in vtkCamera terms (world mm, LPS).

    ``view_angle`` is the vertical full angle in degrees (perspective); ``parallel_scale`` the
    half-height of the view in mm (parallel); ``clipping_range`` the (near, far) distances in mm
    along the direction of projection.
    """

    position: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    focal_point: np.ndarray = field(default_factory=lambda: np.zeros(3))
    view_up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    view_angle: float = 30.0
    parallel_projection: bool = False
    parallel_scale: float = 1.0
    clipping_range: tuple[float, float] = (0.01, 1000.01)

    def __post_init__(self) -> None:
        self.position = _vec(self.position)
        self.focal_point = _vec(self.focal_point)
        self.view_up = _vec(self.view_up)
        if np.linalg.norm(self.focal_point - self.position) <= 0:
            raise ValueError("camera position and focal point coincide")
        if not 0 < self.view_angle < 180:
            raise ValueError(f"view_angle must lie in (0, 180) degrees, got {self.view_angle}")
        near, far = (float(c) for c in self.clipping_range)
        if not 0 < near < far:
            raise ValueError(f"clipping range must satisfy 0 < near < far, got {self.clipping_range}")
        self.clipping_range = (near, far)
        self.view_angle = float(self.view_angle)
        self.parallel_scale = float(self.parallel_scale)
        self.parallel_projection = bool(self.parallel_projection)
        _, up, forward = self.basis()
        # orthogonalised like vtkCamera.OrthogonalizeViewUp(); an up that already is orthonormal is
        # kept bit for bit, so that from_dict(to_dict()) and replace() reproduce the camera exactly
        if abs(float(self.view_up @ forward)) > 1e-12 or abs(float(self.view_up @ self.view_up) - 1.0) > 1e-12:
            self.view_up = up

    # geometry -----------------------------------------------------------------------------
    @property
    def distance(self) -> float:
        """Distance from position to focal point, mm."""
        return float(np.linalg.norm(self.focal_point - self.position))

    @property
    def direction_of_projection(self) -> np.ndarray:
        """Unit vector from position towards the focal point."""
        d = self.focal_point - self.position
        return d / math.sqrt(float(d @ d))

    def pixel_size_at_focus(self, height: int) -> float:
        """mm one pixel of an image ``height`` pixels tall spans on the plane through the focal point
        (square pixels: the projection scales x and y alike)."""
        if self.parallel_projection:
            return 2.0 * self.parallel_scale / height
        return 2.0 * self.distance * math.tan(math.radians(self.view_angle) / 2.0) / height

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Orthonormal (right, up, forward) in world coordinates; forward = direction of projection."""
        forward = self.direction_of_projection
        right = _cross(forward, self.view_up)
        n = math.sqrt(float(right @ right))
        if n < 1e-9:
            raise ValueError("view_up is parallel to the direction of projection")
        right /= n
        up = _cross(right, forward)
        return right, up, forward

    def view_matrix(self) -> np.ndarray:
        """4x4 world -> camera matrix (vtkCamera.GetViewTransformMatrix)."""
        right, up, forward = self.basis()
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = right, up, -forward
        m[:3, 3] = -m[:3, :3] @ self.position
        return m

    def projection_matrix(self, aspect: float) -> np.ndarray:
        """4x4 camera -> clip matrix for width/height ``aspect`` (vtkCamera.GetProjectionTransformMatrix(aspect, -1, 1))."""
        near, far = self.clipping_range
        m = np.zeros((4, 4))
        if self.parallel_projection:
            h = self.parallel_scale
            m[0, 0] = 1.0 / (h * aspect)
            m[1, 1] = 1.0 / h
            m[2, 2] = -2.0 / (far - near)
            m[2, 3] = -(far + near) / (far - near)
            m[3, 3] = 1.0
        else:
            t = math.tan(math.radians(self.view_angle) / 2.0)
            m[0, 0] = 1.0 / (t * aspect)
            m[1, 1] = 1.0 / t
            m[2, 2] = -(far + near) / (far - near)
            m[2, 3] = -2.0 * far * near / (far - near)
            m[3, 2] = -1.0
        return m

    def view_projection(self, aspect: float) -> np.ndarray:
        """4x4 world -> clip matrix."""
        return self.projection_matrix(aspect) @ self.view_matrix()

    def world_to_pixel(self, points: np.ndarray, width: int, height: int) -> np.ndarray:
        """Project world points (..., 3) to continuous pixel coordinates (..., 2), no jitter.

        (0, 0) is the top-left corner of the image; pixel (x, y) has its centre at (x + .5, y + .5).
        """
        p = np.asarray(points, dtype=np.float64)
        h = np.concatenate([p, np.ones(p.shape[:-1] + (1,))], axis=-1)
        clip = h @ self.view_projection(width / height).T
        ndc = clip[..., :2] / clip[..., 3:4]
        return np.stack([(ndc[..., 0] + 1.0) * 0.5 * width, (1.0 - ndc[..., 1]) * 0.5 * height], axis=-1)

    def ray(self, px: float, py: float, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """World origin and unit direction of the ray through continuous pixel position (px, py)."""
        right, up, forward = self.basis()
        aspect = width / height
        nx, ny = 2.0 * px / width - 1.0, 1.0 - 2.0 * py / height
        if self.parallel_projection:
            s = self.parallel_scale
            return self.position + nx * s * aspect * right + ny * s * up, forward
        t = math.tan(math.radians(self.view_angle) / 2.0)
        d = forward + nx * t * aspect * right + ny * t * up
        return self.position.copy(), d / np.linalg.norm(d)

    # motion, as vtkCamera does it; each returns a new camera --------------------------------------
    def azimuth(self, degrees: float) -> "Camera":
        """Rotate the position about the view-up axis through the focal point."""
        r = _rotation(self.view_up, degrees)
        return replace(self, position=self.focal_point + r @ (self.position - self.focal_point))

    def elevation(self, degrees: float) -> "Camera":
        """Rotate the position about the right axis through the focal point (view up follows)."""
        right, _, _ = self.basis()
        r = _rotation(right, -degrees)
        return replace(self, position=self.focal_point + r @ (self.position - self.focal_point),
                       view_up=r @ self.view_up)

    def roll(self, degrees: float) -> "Camera":
        """Rotate the view up about the direction of projection."""
        return replace(self, view_up=_rotation(self.direction_of_projection, degrees) @ self.view_up)

    def zoom(self, factor: float) -> "Camera":
        """Divide the view angle (perspective) or the parallel scale by ``factor`` (>1 zooms in).

        Like vtkCamera.Zoom, the perspective case divides the angle itself, not its tangent.
        """
        if self.parallel_projection:
            return replace(self, parallel_scale=self.parallel_scale / factor)
        return replace(self, view_angle=self.view_angle / factor)

    def dolly(self, factor: float) -> "Camera":
        """Move the position towards the focal point, dividing the distance by ``factor``."""
        return replace(self, position=self.focal_point - self.direction_of_projection * self.distance / factor)

    # framing --------------------------------------------------------------------------------
    @classmethod
    def framing(cls, bounds: Bounds, direction: Sequence[float] = (0.0, 1.0, 0.0),
                view_up: Sequence[float] = (0.0, 0.0, 1.0), view_angle: float = 30.0,
                parallel_projection: bool = False, margin: float = 1.0, aspect: float = 1.0) -> "Camera":
        """A camera looking along ``direction`` that frames ``bounds`` (vtkRenderer.ResetCamera).

        As in VTK, the bounding sphere of ``bounds`` (times ``margin``) touches the view: vertically
        for a landscape image (``aspect`` = width / height >= 1), horizontally for a portrait one.
        VTK also forces the view angle to 30 degrees; here ``view_angle`` is kept.
        The default is an anterior view: the camera stands on the patient's front (-y in LPS)
        looking towards +y (posterior), with superior (+z in LPS) at the top of the image.
        """
        b = np.asarray(bounds, dtype=np.float64).reshape(3, 2)
        center = b.mean(axis=1)
        radius = 0.5 * float(np.linalg.norm(b[:, 1] - b[:, 0])) * margin
        d = _vec(direction)
        d /= np.linalg.norm(d)
        half_angle, scale = math.radians(view_angle) / 2.0, radius
        if aspect < 1.0:
            half_angle, scale = math.atan(math.tan(half_angle) * aspect), radius / aspect
        dist = radius / math.sin(half_angle)
        cam = cls(position=center - d * dist, focal_point=center, view_up=view_up, view_angle=view_angle,
                  parallel_projection=parallel_projection, parallel_scale=scale)
        return cam.reset_clipping_range(bounds)

    def reset_clipping_range(self, bounds: Bounds, slack: float = 0.01) -> "Camera":
        """Near/far planes that enclose ``bounds`` (vtkRenderer.ResetCameraClippingRange)."""
        b = np.asarray(bounds, dtype=np.float64).reshape(3, 2)
        corners = np.array([[x, y, z] for x in b[0] for y in b[1] for z in b[2]])
        depth = (corners - self.position) @ self.direction_of_projection
        span = max(float(depth.max() - depth.min()), 1e-6)
        near = max(float(depth.min()) - slack * span, 1e-3 * max(float(depth.max()), 1e-3))
        far = max(float(depth.max()) + slack * span, near * 1.001)
        return replace(self, clipping_range=(near, far))

    # serialisation (the camera-path JSON format) --------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """vtkCamera terms, JSON-ready."""
        return {
            "position": self.position.tolist(),
            "focal_point": self.focal_point.tolist(),
            "view_up": self.view_up.tolist(),
            "view_angle": self.view_angle,
            "parallel_projection": self.parallel_projection,
            "parallel_scale": self.parallel_scale,
            "clipping_range": list(self.clipping_range),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Camera":
        unknown = sorted(set(d) - set(cls.__dataclass_fields__))
        if unknown:
            raise ValueError(f"unknown camera keys: {', '.join(unknown)}")
        for key in ("position", "focal_point"):
            if key not in d:
                raise ValueError(f"camera lacks '{key}'")
        return cls(**d)


def rigid_matrix(matrix: Any) -> np.ndarray:
    """``matrix`` as a 4x4 float64 array, checked to be a rotation (det +1) plus a translation."""
    m = np.asarray(matrix, dtype=np.float64)
    if m.shape != (4, 4) or not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0)):
        raise ValueError(f"expected a 4x4 affine matrix, got shape {m.shape}")
    r = m[:3, :3]
    if not np.allclose(r.T @ r, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
        raise ValueError("the world matrix must be rigid: a rotation (det +1, no mirror, no scale) plus a translation")
    return m


def transform_camera(camera: Camera, matrix: Any) -> Camera:
    """``camera`` carried by the rigid 4x4 ``matrix`` (position, focal point, view up); the image it
    sees of a scene carried by the same matrix is unchanged."""
    m = rigid_matrix(matrix)
    r, t = m[:3, :3], m[:3, 3]
    return replace(camera, position=r @ camera.position + t, focal_point=r @ camera.focal_point + t,
                               view_up=r @ camera.view_up)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a`` x ``b`` of two 3-vectors, float64: np.cross's checks cost it about 23 µs a call, twenty times this."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array((a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0))


def rotation_between(a: Camera, b: Camera) -> float:
    """Angle in degrees of the rotation taking camera ``a``'s (right, up, forward) frame to ``b``'s."""
    cos = (sum(float(u @ v) for u, v in zip(a.basis(), b.basis())) - 1.0) / 2.0  # (trace(Rb Ra^T) - 1) / 2
    return math.degrees(math.acos(min(max(cos, -1.0), 1.0)))  # a float clamped: np.clip took 4 µs a call
