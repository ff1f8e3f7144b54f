"""Camera paths: orbits, pools of random viewpoints, smooth random motion, and their JSON files.

Everything is in world millimetres (LPS) and every path is a list of :class:`Camera`. Angles are
in degrees. A camera-path file is UTF-8 JSON::

    {"format": "volsr-camera-path", "version": 1, "cameras": [Camera.to_dict(), ...]}

with cameras in vtkCamera terms (position, focal_point, view_up, view_angle, parallel_projection,
parallel_scale, clipping_range); a bare list of camera objects is read as well.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from volsr_core.atomic import atomic_write
from volsr_core.errors import InputError
from volsr_core.scene.camera import Bounds, Camera, _rotation

FORMAT = "volsr-camera-path"
VERSION = 1
SUPERIOR = np.array([0.0, 0.0, 1.0])  # LPS +z: the head, the default image "up"
ANTERIOR = np.array([0.0, -1.0, 0.0])  # LPS -y: image "up" for views along the body axis


# orbits -----------------------------------------------------------------------------------------
def orbit(start: Camera, n_frames: int, degrees: float = 360.0, elevation: float = 0.0) -> list[Camera]:
    """``n_frames`` cameras turning about the focal point, ``degrees / n_frames`` apart.

    Frame 0 is ``start.elevation(elevation)``; the others turn it about the axis through the focal
    point along ``start.view_up`` (a turntable, so every frame keeps the same elevation; with
    ``elevation=0`` frame i is ``start.azimuth(i * degrees / n_frames)``). A full turn does not
    repeat frame 0 at its end, so the frames loop seamlessly.
    """
    if n_frames < 1:
        raise ValueError(f"n_frames must be at least 1, got {n_frames}")
    base = start.elevation(elevation)
    step = degrees / n_frames
    return [_turn(base, start.view_up, i * step) for i in range(n_frames)]


def orbit_framing(bounds: Bounds, aspect: float = 1.0, view_angle: float = 30.0, fill: float = 0.9) -> Camera:
    """The anterior view (as :meth:`Camera.framing`) of the box ``bounds`` at the distance where the box,
    turning about the superior axis through its centre (a turntable orbit), fills ``fill`` of the view.

    :meth:`Camera.framing` fits the box's bounding sphere, which leaves a tall or flat box small; here
    the cylinder the turning box sweeps (radius: the box's half diagonal across the axis; half height:
    its half extent along it) must fit, vertically and horizontally, seen in perspective from the
    nearest point of the cylinder.
    """
    b = np.asarray(bounds, dtype=np.float64).reshape(3, 2)
    radius = 0.5 * float(np.hypot(b[0, 1] - b[0, 0], b[1, 1] - b[1, 0]))
    half_height = 0.5 * float(b[2, 1] - b[2, 0])
    tan_v = math.tan(math.radians(view_angle) / 2.0) * fill
    tan_h = math.tan(math.radians(view_angle) / 2.0) * aspect * fill
    distance = max(radius + half_height / tan_v, radius * math.sqrt(1.0 + 1.0 / (tan_h * tan_h)))
    start = Camera.framing(bounds, view_angle=view_angle, aspect=aspect)
    return start.dolly(start.distance / distance).reset_clipping_range(bounds)


def orbit_around(bounds: Bounds, n_frames: int, degrees_per_frame: float | None = None, elevation: float = 0.0,
                 aspect: float = 1.0, fill: float | None = 0.9) -> list[Camera]:
    """``n_frames`` cameras orbiting the box ``bounds`` (mm; the volume's, or what its transfer function
    shows: ``RayCaster.visible_bounds``) from the anterior view that fills ``fill`` of the view with it
    (:func:`orbit_framing`; None: VTK's ResetCamera framing of the bounding sphere,
    :meth:`Camera.framing`), ``degrees_per_frame`` apart (None: one full turn over the frames),
    ``elevation`` degrees up, clipping ranges fitted to ``bounds``: the commands' ``--orbit``."""
    degrees = 360.0 if degrees_per_frame is None else n_frames * degrees_per_frame
    start = Camera.framing(bounds, aspect=aspect) if fill is None else orbit_framing(bounds, aspect=aspect, fill=fill)
    return [c.reset_clipping_range(bounds) for c in orbit(start, n_frames, degrees, elevation=elevation)]


def _turn(camera: Camera, axis: np.ndarray, degrees: float) -> Camera:
    """Rotate position and view up about ``axis`` through the focal point (right-handed)."""
    r = _rotation(np.asarray(axis, dtype=np.float64), degrees)
    return replace(camera, position=camera.focal_point + r @ (camera.position - camera.focal_point),
                   view_up=r @ camera.view_up)


# random viewpoints ------------------------------------------------------------------------------
def candidate_pool(bounds: Bounds, n: int, rng: np.random.Generator, view_angle: float = 30.0,
                   distance_range: tuple[float, float] = (0.9, 1.6), max_roll: float = 20.0,
                   focal_jitter: float = 0.05) -> list[Camera]:
    """``n`` cameras around the centre of ``bounds`` (xmin, xmax, ymin, ymax, zmin, zmax; mm).

    Viewing directions are a Fibonacci sphere, randomly rotated and shuffled by ``rng``, so they
    cover the sphere evenly. Each camera stands at a random multiple (``distance_range``) of the
    framing distance (:meth:`Camera.framing`, the bounding sphere just filling the view angle),
    looks at the centre moved by up to ``focal_jitter`` times the bounding radius along each axis,
    has superior (anterior for views along the body axis) up, rolled by at most ``max_roll``, a
    parallel scale that frames the same as its distance, and its clipping range reset to ``bounds``.
    """
    if n < 1:
        raise ValueError(f"n must be at least 1, got {n}")
    b = np.asarray(bounds, dtype=np.float64).reshape(3, 2)
    centre, radius = b.mean(axis=1), 0.5 * float(np.linalg.norm(b[:, 1] - b[:, 0]))
    framing_distance = radius / math.sin(math.radians(view_angle) / 2.0)
    directions = _fibonacci_sphere(n) @ _random_rotation(rng).T
    cameras = []
    for d in directions[rng.permutation(n)]:
        factor = float(rng.uniform(*distance_range))
        focal = centre + rng.uniform(-1.0, 1.0, size=3) * focal_jitter * radius
        up = SUPERIOR if abs(float(d @ SUPERIOR)) < 0.9 else ANTERIOR
        camera = Camera(position=focal - d * framing_distance * factor, focal_point=focal, view_up=up,
                        view_angle=view_angle, parallel_scale=radius * factor)
        cameras.append(camera.roll(float(rng.uniform(-max_roll, max_roll))).reset_clipping_range(bounds))
    return cameras


def random_start(pool: Sequence[Camera], rng: np.random.Generator) -> Camera:
    """One camera of ``pool``, chosen uniformly by ``rng``."""
    if len(pool) == 0:
        raise ValueError("the camera pool is empty")
    return pool[int(rng.integers(len(pool)))]


def _fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (golden-angle spiral)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = math.pi * (3.0 - math.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random 3x3 rotation (QR of a Gaussian matrix, signs fixed)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


# smooth random motion ---------------------------------------------------------------------------
def smooth_random_path(start: Camera, n_frames: int, rng: np.random.Generator, bounds: Bounds | None = None,
                       max_orbit_speed: float = 3.0, max_elevation_speed: float = 1.5,
                       zoom_range: tuple[float, float] = (0.8, 1.5), max_elevation: float = 60.0,
                       max_zoom_speed: float = 0.01, period: int = 30) -> list[Camera]:
    """A camera that orbits, rises and falls and zooms smoothly, as in a video; frame 0 is ``start``.

    Three signals are drawn from ``rng`` as random keyframes every ``period`` frames joined by
    cosine interpolation (C1, so no jerks): the orbit *speed* about ``start.view_up`` through the
    focal point (mostly in one random sense, at most ``max_orbit_speed`` deg/frame); the
    elevation above the start's horizon (within +-``max_elevation`` deg, at most
    ``max_elevation_speed`` deg/frame); and the zoom factor relative to ``start`` (within
    ``zoom_range``, log-uniform, changing by at most ``max_zoom_speed`` per frame).
    Successive view directions therefore differ by at most ``max_orbit_speed + max_elevation_speed``
    degrees; the view up stays orthogonal to the view direction and never flips over the pole
    (``max_elevation`` < 90). With ``bounds`` every clipping range is reset to enclose them.
    """
    if n_frames < 1 or period < 1:
        raise ValueError(f"n_frames and period must be at least 1, got {n_frames} and {period}")
    if not 0.0 < max_elevation < 90.0:
        raise ValueError(f"max_elevation must lie in (0, 90) degrees, got {max_elevation}")
    if not 0.0 < zoom_range[0] <= 1.0 <= zoom_range[1]:
        raise ValueError(f"zoom_range must contain 1 (the start), got {zoom_range}")
    n_keys = n_frames // period + 2
    sense = 1.0 if rng.random() < 0.5 else -1.0
    speed = _ease(sense * max_orbit_speed * rng.uniform(-0.25, 1.0, size=n_keys), period, n_frames)
    azimuth = np.concatenate([[0.0], np.cumsum(speed[:-1])])
    elevation = _ease(_bounded_walk(rng, n_keys, max_elevation, _reach(max_elevation_speed, period)),
                      period, n_frames)
    log_zoom = _ease(_bounded_walk(rng, n_keys, (math.log(zoom_range[0]), math.log(zoom_range[1])),
                                   _reach(math.log1p(max_zoom_speed), period)), period, n_frames)
    cameras = []
    for a, e, z in zip(azimuth, elevation, log_zoom):
        camera = _turn(start.elevation(float(e)), start.view_up, float(a)).zoom(math.exp(z))
        cameras.append(camera if bounds is None else camera.reset_clipping_range(bounds))
    return cameras


def _reach(max_speed: float, period: int) -> float:
    """Largest keyframe step whose cosine easing over ``period`` frames peaks at ``max_speed`` per frame."""
    return 2.0 * period * max_speed / math.pi


def _bounded_walk(rng: np.random.Generator, n: int, limits: float | tuple[float, float], reach: float) -> np.ndarray:
    """``n`` keyframes starting at 0, each within ``reach`` of the last and inside ``limits``
    (a (low, high) pair, or +-limits)."""
    low, high = (-limits, limits) if np.isscalar(limits) else limits
    keys = np.zeros(n)
    for k in range(1, n):
        keys[k] = rng.uniform(max(low, keys[k - 1] - reach), min(high, keys[k - 1] + reach))
    return keys


def _ease(keys: np.ndarray, period: int, n: int) -> np.ndarray:
    """``n`` samples passing through ``keys[k]`` at frame ``k * period``, cosine-eased in between."""
    t = np.arange(n)
    k = t // period
    w = 0.5 - 0.5 * np.cos(math.pi * (t % period) / period)
    return keys[k] * (1.0 - w) + keys[k + 1] * w


# files ------------------------------------------------------------------------------------------
def write_camera_path(path: str | os.PathLike, cameras: Sequence[Camera]) -> None:
    """Write ``cameras`` as a camera-path JSON file, atomically (temporary file, then rename)."""
    if len(cameras) == 0:
        raise ValueError("a camera path needs at least one camera")
    doc = {"format": FORMAT, "version": VERSION, "cameras": [c.to_dict() for c in cameras]}
    with atomic_write(path, "w", encoding="utf-8") as fh:
        json.dump(doc, fh, indent=1)
        fh.write("\n")


def read_camera_path(path: str | os.PathLike) -> list[Camera]:
    """Cameras from a camera-path JSON file (or a bare JSON list of camera objects).

    Raises :class:`InputError` ("<path>: <problem>", one line) for a missing or unreadable file,
    invalid JSON, a wrong structure, an empty list, or a bad camera (naming its index).
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except IsADirectoryError:
        raise InputError(path, "is a folder, not a camera-path file") from None
    except UnicodeDecodeError:
        raise InputError(path, "not a text file (camera paths are UTF-8 JSON)") from None
    except OSError as err:
        raise InputError(path, f"cannot read: {err.strerror or err}") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as err:
        raise InputError(path, f"not valid JSON: {err.msg} at line {err.lineno}, column {err.colno}") from None
    items = _camera_items(path, doc)
    if not items:
        raise InputError(path, "contains no cameras")
    return [_camera(path, i, item) for i, item in enumerate(items)]


def _camera_items(path: str | os.PathLike, doc: Any) -> list:
    """The list of camera objects in a parsed file, checking the envelope."""
    if isinstance(doc, list):
        return doc
    if not isinstance(doc, dict):
        raise InputError(path, f"expected a JSON object or list of cameras, got {type(doc).__name__}")
    if doc.get("format") != FORMAT:
        raise InputError(path, f"not a camera-path file: 'format' is {doc.get('format')!r}, expected {FORMAT!r}")
    if doc.get("version") != VERSION:
        raise InputError(path, f"unsupported camera-path version {doc.get('version')!r} (this VolSR reads {VERSION})")
    if not isinstance(doc.get("cameras"), list):
        raise InputError(path, "'cameras' must be a list of camera objects")
    return doc["cameras"]


def _camera(path: str | os.PathLike, index: int, item: Any) -> Camera:
    if not isinstance(item, dict):
        raise InputError(path, f"camera {index}: expected an object, got {type(item).__name__}")
    try:
        return Camera.from_dict(item)
    except (ValueError, TypeError) as err:
        raise InputError(path, f"camera {index}: {err}") from None
