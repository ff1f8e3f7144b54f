"""A deterministic synthetic CT of a torso and head, in Hounsfield units, generated from a seed.

The anatomy is laid out in *body units*: every world axis is scaled so that the voxel centres
run from -1 to +1, i.e. ``u = world_mm / half_extent`` per axis, and the body is fitted to the
box whatever its shape or spacing. Axes are LPS like the world: +x is the patient's left, +y
posterior, +z superior (the head is at +z). Distances inside the generator (layer depths,
radii) are in body units too; one voxel is ``2 / (n - 1)`` of them.

What is in it: air (-1000 HU, exactly) around a body of soft tissue (~45 HU) under a thin
skin (~70 HU) and a subcutaneous fat layer (~-100 HU); a brain (~35 HU) and a liver (~60 HU);
two lungs (~-850 HU with a faint texture); bone (800-1200 HU) as a ribcage with intercostal
gaps, a sternum, a segmented spine and a skull with orbits, an open base and a few burr holes;
contrast-filled vessels (~330-370 HU: an aorta with iliac and carotid branches plus random
branches, some of them branching again) along smooth random curves; a few HU of smooth noise
inside the body. Boundaries are partial-volume blended over about one voxel. The seed moves the
vessels, the burr holes, the contrast level and the noise; the organs stay where
:func:`phantom_landmarks` says.
"""
from __future__ import annotations

import math

import numpy as np

from volsr_core.io.record import VolumeRecord

AIR_HU = -1000.0
SKIN_HU = 70.0
FAT_HU = -100.0
SOFT_HU = 45.0
BRAIN_HU = 35.0
LIVER_HU = 60.0
LUNG_HU = -850.0
BONE_HU = (800.0, 1200.0)  # bone surface, bone deeper than BONE_RAMP
CONTRAST_HU = (330.0, 370.0)  # drawn once per seed
HU_RANGE = (-1024.0, 3071.0)

# anatomy, body units (centre x, y, z) and radii -------------------------------------------------
TORSO_CENTRE, TORSO_RADII, TORSO_HALF_Z, TORSO_ROUNDING = (0.0, 0.0, -0.31), (0.86, 0.58), 0.65, 0.2
NECK_CENTRE, NECK_RADII, NECK_Z = (0.0, 0.06), (0.22, 0.26), (0.2, 0.55)
HEAD_CENTRE, HEAD_RADII = (0.0, 0.02, 0.70), (0.27, 0.32, 0.26)
LUNG_CENTRES, LUNG_RADII = ((-0.35, 0.04, -0.06), (0.35, 0.04, -0.06)), (0.24, 0.30, 0.28)
LIVER_CENTRE, LIVER_RADII = (-0.30, -0.02, -0.47), (0.36, 0.32, 0.17)
SKIN = 0.03
FAT_TORSO, FAT_HEAD = 0.10, 0.03
RIB_DEPTH, RIB_HALF_THICKNESS, RIB_PITCH, RIB_HALF_WIDTH, RIB_SLOPE = 0.18, 0.03, 0.11, 0.022, 0.35
SKULL_DEPTH, SKULL_HALF_THICKNESS = 0.075, 0.028
ORBITS, ORBIT_RADIUS = ((-0.10, -0.20, 0.66), (0.10, -0.20, 0.66)), 0.07
BONE_RAMP = 0.03  # bone reaches BONE_HU[1] this deep inside its surface
NOISE_HU, LUNG_TEXTURE_HU = 4.0, 25.0


def make_phantom(seed: int = 0, shape: tuple[int, int, int] = (128, 128, 128),
                 spacing: tuple[float, float, float] = (1.5, 1.5, 1.5)) -> VolumeRecord:
    """Synthetic CT (HU) of a torso and head; the same seed gives the same float32 array.

    ``shape`` is the array shape (z, y, x); ``spacing`` the voxel size (x, y, z) in mm. The origin
    puts the centre of the voxel-centre box at world (0, 0, 0); the direction is the identity (LPS).
    """
    shape = tuple(int(n) for n in shape)
    if len(shape) != 3 or min(shape) < 2:
        raise ValueError(f"shape must be three sizes >= 2 (z, y, x), got {shape}")
    rng = np.random.default_rng(seed)
    tubes, contrast, holes = _vessel_tree(rng), float(rng.uniform(*CONTRAST_HU)), _burr_holes(rng)
    noise, texture = _value_noise(rng, shape, 10), _value_noise(rng, shape, 14)
    x, y, z = _body_axes(shape)
    ramp = float(np.mean([2.0 / (n - 1) for n in shape]))
    section, head, body = _body_sdfs(x, y, z)
    fat = FAT_TORSO + (FAT_HEAD - FAT_TORSO) * _smoothstep(0.25, 0.5, z)
    interior = _inside(body + SKIN + fat, ramp)

    hu = _layers(-body, fat, ramp)
    hu = _mix(hu, BRAIN_HU, _inside(head + SKULL_DEPTH + SKULL_HALF_THICKNESS, ramp))
    hu = _mix(hu, LIVER_HU, interior * _inside(_ellipsoid_sdf(x, y, z, LIVER_CENTRE, LIVER_RADII), ramp))
    hu = _mix(hu, contrast, interior * _rasterise_tubes(tubes, shape, ramp))
    lungs = np.minimum(*(_ellipsoid_sdf(x, y, z, c, LUNG_RADII) for c in LUNG_CENTRES))
    hu = _mix(hu, LUNG_HU + LUNG_TEXTURE_HU * texture, _inside(lungs, ramp))
    bone = np.minimum(np.minimum(_ribcage_sdf(x, y, z, -section), _spine_sdf(x, y, z)),
                      _skull_sdf(x, y, z, -head, holes))
    bone_hu = BONE_HU[0] + (BONE_HU[1] - BONE_HU[0]) * np.clip(-bone / BONE_RAMP, 0.0, 1.0)
    hu = _mix(hu, bone_hu, _inside(bone, ramp))
    hu += NOISE_HU * noise * _inside(body, ramp)
    np.clip(hu, *HU_RANGE, out=hu)
    return VolumeRecord(array=hu.astype(np.float32), spacing=tuple(float(s) for s in spacing),
                        origin=_centred_origin(shape, spacing), direction=np.eye(3), modality="CT",
                        units="HU", source=f"phantom(seed={seed})")


def phantom_landmarks(shape: tuple[int, int, int] = (128, 128, 128),
                      spacing: tuple[float, float, float] = (1.5, 1.5, 1.5)) -> dict[str, np.ndarray]:
    """World positions (mm, LPS) of organ centres in :func:`make_phantom` with this shape/spacing.

    Keys: ``right_lung`` and ``left_lung`` (the patient's right is -x), ``liver`` and ``brain``.
    They do not depend on the seed.
    """
    half = _half_extent(shape, spacing)
    centres = {"right_lung": LUNG_CENTRES[0], "left_lung": LUNG_CENTRES[1], "liver": LIVER_CENTRE,
               "brain": HEAD_CENTRE}
    return {name: np.asarray(c, dtype=np.float64) * half for name, c in centres.items()}


# geometry helpers ---------------------------------------------------------------------------------
def _half_extent(shape: tuple[int, int, int], spacing: tuple[float, float, float]) -> np.ndarray:
    """Half the voxel-centre box size along (x, y, z), mm: world = body units * this."""
    nz, ny, nx = shape
    return np.asarray(spacing, dtype=np.float64) * (np.array([nx, ny, nz]) - 1) / 2.0


def _centred_origin(shape: tuple[int, int, int], spacing: tuple[float, float, float]) -> tuple[float, float, float]:
    """World position (mm) of voxel (0, 0, 0) that puts the box centre at the world origin."""
    return tuple(float(v) for v in -_half_extent(shape, spacing))


def _body_axes(shape: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Broadcastable float32 body-unit coordinates x (1, 1, nx), y (1, ny, 1), z (nz, 1, 1) in [-1, 1]."""
    nz, ny, nx = shape
    axis = [np.linspace(-1.0, 1.0, n, dtype=np.float32) for n in (nx, ny, nz)]
    return axis[0][None, None, :], axis[1][None, :, None], axis[2][:, None, None]


def _ellipse_sdf(a: np.ndarray, b: np.ndarray, radii: tuple[float, float]) -> np.ndarray:
    """Approximate signed distance to an ellipse (negative inside), exact on its axes."""
    k0 = np.sqrt((a / radii[0]) ** 2 + (b / radii[1]) ** 2)
    k1 = np.sqrt((a / radii[0] ** 2) ** 2 + (b / radii[1] ** 2) ** 2)
    return k0 * (k0 - 1.0) / np.maximum(k1, 1e-6)


def _ellipsoid_sdf(x: np.ndarray, y: np.ndarray, z: np.ndarray, centre: tuple[float, float, float],
                   radii: tuple[float, float, float]) -> np.ndarray:
    """Approximate signed distance to an ellipsoid (negative inside), exact on its axes."""
    p = (x - centre[0], y - centre[1], z - centre[2])
    k0 = np.sqrt(sum((pi / ri) ** 2 for pi, ri in zip(p, radii)))
    k1 = np.sqrt(sum((pi / ri ** 2) ** 2 for pi, ri in zip(p, radii)))
    return k0 * (k0 - 1.0) / np.maximum(k1, 1e-6)


def _rounded_prism(section: np.ndarray, dz: np.ndarray, rounding: float) -> np.ndarray:
    """Signed distance of a prism from its cross-section distance and |z| - half height, edges rounded."""
    a, b = section + rounding, dz + rounding
    outside = np.sqrt(np.maximum(a, 0.0) ** 2 + np.maximum(b, 0.0) ** 2)
    return outside + np.minimum(np.maximum(a, b), 0.0) - rounding


def _smooth_union(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth minimum of two distance fields; blends over about ``k`` body units."""
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b + (a - b) * h - k * h * (1.0 - h)


def _smoothstep(lo: float, hi: float, t: np.ndarray) -> np.ndarray:
    """0 below ``lo``, 1 above ``hi``, a C1 cubic in between."""
    s = np.clip((t - lo) / (hi - lo), 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def _inside(sdf: np.ndarray, ramp: float) -> np.ndarray:
    """Partial-volume fraction (0..1) of a voxel inside a surface, linear over one ``ramp``."""
    return np.clip(0.5 - sdf / ramp, 0.0, 1.0)


def _mix(hu: np.ndarray, value: np.ndarray | float, fraction: np.ndarray) -> np.ndarray:
    """``hu`` with ``fraction`` (0..1) of each voxel replaced by ``value`` (HU)."""
    return hu + (value - hu) * fraction


# tissues -----------------------------------------------------------------------------------------
def _body_sdfs(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed distances (body units, negative inside) of the torso's cross-section (a vertical
    elliptic cylinder, for the ribcage), the head, and the whole body (torso, neck and head blended)."""
    section = _ellipse_sdf(x - TORSO_CENTRE[0], y - TORSO_CENTRE[1], TORSO_RADII)
    torso = _rounded_prism(section, np.abs(z - TORSO_CENTRE[2]) - TORSO_HALF_Z, TORSO_ROUNDING)
    head = _ellipsoid_sdf(x, y, z, HEAD_CENTRE, HEAD_RADII)
    return section, head, _smooth_union(_smooth_union(torso, _neck_sdf(x, y, z), 0.08), head, 0.08)


def _neck_sdf(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Signed distance of the neck, a short elliptic cylinder between torso and head."""
    section = _ellipse_sdf(x - NECK_CENTRE[0], y - NECK_CENTRE[1], NECK_RADII)
    middle, half = 0.5 * (NECK_Z[0] + NECK_Z[1]), 0.5 * (NECK_Z[1] - NECK_Z[0])
    return _rounded_prism(section, np.abs(z - middle) - half, 0.05)


def _layers(depth: np.ndarray, fat: np.ndarray, ramp: float) -> np.ndarray:
    """Air, skin, subcutaneous fat and soft tissue by depth below the body surface (body units)."""
    hu = AIR_HU + (SKIN_HU - AIR_HU) * _inside(-depth, ramp)
    hu += (FAT_HU - SKIN_HU) * _inside(SKIN - depth, ramp)
    hu += (SOFT_HU - FAT_HU) * _inside(SKIN + fat - depth, ramp)
    return hu


def _ribcage_sdf(x: np.ndarray, y: np.ndarray, z: np.ndarray, wall_depth: np.ndarray) -> np.ndarray:
    """Ribs (sloping down anteriorly, with intercostal gaps and an anterior cartilage gap) and sternum."""
    shell = np.abs(wall_depth - RIB_DEPTH) - RIB_HALF_THICKNESS
    level = z - RIB_SLOPE * y  # constant along one rib
    across = np.abs(np.mod(level, RIB_PITCH) - 0.5 * RIB_PITCH) - RIB_HALF_WIDTH
    extent = np.maximum(level - 0.10, -0.48 - level)
    cartilage_gap = np.maximum(np.abs(x) - 0.2, y)
    ribs = np.maximum(np.maximum(shell, across), np.maximum(extent, -cartilage_gap))
    sternum = np.maximum(np.maximum(shell, np.abs(x) - 0.06), np.maximum(y + 0.1, np.maximum(z - 0.2, -0.3 - z)))
    return np.minimum(ribs, sternum)


def _spine_sdf(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Vertebral bodies and posterior arches along a column that moves forward in the neck; discs between."""
    column = 0.26 + (0.10 - 0.26) * _smoothstep(0.22, 0.46, z)
    bodies = np.sqrt(x * x + (y - column) ** 2) - 0.075
    arches = np.abs(np.sqrt(x * x + (y - column - 0.12) ** 2) - 0.05) - 0.017
    discs = 0.012 - np.abs(np.mod(z, 0.1) - 0.05)
    extent = np.maximum(z - 0.52, -0.86 - z)
    return np.maximum(np.maximum(np.minimum(bodies, arches), discs), extent)


def _skull_sdf(x: np.ndarray, y: np.ndarray, z: np.ndarray, head_depth: np.ndarray,
               holes: list[tuple[np.ndarray, float]]) -> np.ndarray:
    """Skull shell open at its base, with two orbits and the seed's burr holes cut out."""
    skull = np.maximum(np.abs(head_depth - SKULL_DEPTH) - SKULL_HALF_THICKNESS, 0.52 - z)
    for centre, radius in [(np.asarray(c), ORBIT_RADIUS) for c in ORBITS] + holes:
        hole = np.sqrt((x - centre[0]) ** 2 + (y - centre[1]) ** 2 + (z - centre[2]) ** 2) - radius
        skull = np.maximum(skull, -hole)
    return skull


def _burr_holes(rng: np.random.Generator) -> list[tuple[np.ndarray, float]]:
    """Two to four small holes on the upper skull, (centre, radius) in body units."""
    holes = []
    for _ in range(int(rng.integers(2, 5))):
        theta, phi = rng.uniform(0.0, 2.0 * math.pi), rng.uniform(0.2, 1.0)
        unit = np.array([math.sin(phi) * math.cos(theta), math.sin(phi) * math.sin(theta), math.cos(phi)])
        surface = np.asarray(HEAD_CENTRE) + unit * (np.asarray(HEAD_RADII) - SKULL_DEPTH)
        holes.append((surface, float(rng.uniform(0.025, 0.04))))
    return holes


def _value_noise(rng: np.random.Generator, shape: tuple[int, int, int], cells: int) -> np.ndarray:
    """Smooth float32 noise in [-1, 1]: a random (cells+1)^3 lattice, smoothstep-interpolated."""
    out = rng.uniform(-1.0, 1.0, size=(cells + 1,) * 3).astype(np.float32)
    for axis, n in enumerate(shape):
        t = np.linspace(0.0, cells, n)
        i0 = np.minimum(t.astype(np.int64), cells - 1)
        w = t - i0
        w = (w * w * (3.0 - 2.0 * w)).astype(np.float32)
        w = w.reshape([-1 if a == axis else 1 for a in range(3)])
        out = np.take(out, i0, axis=axis) * (1.0 - w) + np.take(out, i0 + 1, axis=axis) * w
    return out


# vessels -----------------------------------------------------------------------------------------
Tube = tuple[np.ndarray, np.ndarray]  # (m, 3) centre-line samples (x, y, z) and (m,) radii, body units

AORTA = [(0.00, -0.10, -0.02), (0.00, -0.08, 0.12), (0.03, 0.02, 0.19), (0.06, 0.10, 0.12),
         (0.07, 0.10, -0.05), (0.06, 0.10, -0.35), (0.03, 0.08, -0.55), (0.0, 0.06, -0.70)]
ILIAC = [(0.0, 0.06, -0.70), (0.08, 0.05, -0.76), (0.18, 0.02, -0.80), (0.28, -0.02, -0.82)]
CAROTID = [(0.03, 0.02, 0.19), (0.08, -0.02, 0.30), (0.11, -0.04, 0.42), (0.11, -0.02, 0.54),
           (0.09, 0.02, 0.66), (0.06, 0.04, 0.78)]


def _vessel_tree(rng: np.random.Generator) -> list[Tube]:
    """Aorta, iliac and carotid arteries with seed-jittered courses, plus random side branches."""
    aorta = _tube(_jitter(rng, AORTA), 0.065, 0.05, rng)
    tubes = [aorta]
    for side in (-1.0, 1.0):
        mirror = np.array([side, 1.0, 1.0])
        tubes.append(_tube(_jitter(rng, np.asarray(ILIAC) * mirror), 0.045, 0.035, rng))
        carotid = _tube(_jitter(rng, np.asarray(CAROTID) * mirror), 0.035, 0.025, rng)
        tubes.append(carotid)
        for _ in range(int(rng.integers(2, 4))):  # cerebral branches
            tubes += _branch(rng, carotid, (0.75, 1.0), 0.022, up=0.0, reach=(0.04, 0.07))
    for _ in range(int(rng.integers(3, 6))):  # visceral branches of the descending aorta
        tubes += _branch(rng, aorta, (0.45, 0.95), 0.032, up=-0.2, reach=(0.08, 0.13))
    return tubes


def _jitter(rng: np.random.Generator, points: np.ndarray | list, sigma: float = 0.012) -> np.ndarray:
    """Control points moved by Gaussian noise, the first one kept (it joins the parent vessel)."""
    p = np.array(points, dtype=np.float64)
    p[1:] += rng.normal(0.0, sigma, size=p[1:].shape)
    return p


def _branch(rng: np.random.Generator, parent: Tube, along: tuple[float, float], radius: float,
            up: float, reach: tuple[float, float], depth: int = 0) -> list[Tube]:
    """A random curved branch leaving ``parent`` somewhere in the ``along`` fraction of its length.

    It heads sideways (plus ``up`` times superior), bending at each of its five control points
    ``reach`` body units apart; the first level may split once more near its middle.
    """
    points, _ = parent
    start = points[int(rng.uniform(*along) * (len(points) - 1))]
    heading = np.array([*rng.normal(size=2), up + 0.3 * rng.normal()])
    control = [start]
    for _ in range(5):
        heading = heading / np.linalg.norm(heading) + 0.35 * rng.normal(size=3)
        control.append(control[-1] + rng.uniform(*reach) * heading / np.linalg.norm(heading))
    tube = _tube(np.array(control), radius, 0.6 * radius, rng)
    tubes = [tube]
    if depth == 0 and rng.random() < 0.5:
        tubes += _branch(rng, tube, (0.3, 0.7), 0.7 * radius, up, reach, depth + 1)
    return tubes


def _tube(control: np.ndarray, r0: float, r1: float, rng: np.random.Generator) -> Tube:
    """Centre line through ``control`` (Catmull-Rom) sampled every third of the smallest radius,
    with the radius tapering from ``r0`` to ``r1`` and a gentle random swelling."""
    step = min(r0, r1) / 3.0
    points = _catmull_rom(control, step)
    t = np.linspace(0.0, 1.0, len(points))
    swell = 1.0 + 0.12 * np.sin(2.0 * math.pi * rng.uniform(0.5, 2.0) * t + rng.uniform(0.0, 2.0 * math.pi))
    return points, (r0 + (r1 - r0) * t) * swell


def _catmull_rom(control: np.ndarray, step: float) -> np.ndarray:
    """Points along the uniform Catmull-Rom spline through ``control`` (m, 3), about ``step`` apart."""
    p = np.concatenate([control[:1], control, control[-1:]])
    pieces = []
    for i in range(1, len(p) - 2):
        n = max(2, int(math.ceil(np.linalg.norm(p[i + 1] - p[i]) / step)))
        t = np.linspace(0.0, 1.0, n, endpoint=False)[:, None]
        a, b, c, d = p[i - 1], p[i], p[i + 1], p[i + 2]
        cubic = (2 * a - 5 * b + 4 * c - d) * t ** 2 + (3 * b - a - 3 * c + d) * t ** 3
        pieces.append(0.5 * (2 * b + (c - a) * t + cubic))
    pieces.append(control[-1:])
    return np.concatenate(pieces)


def _rasterise_tubes(tubes: list[Tube], shape: tuple[int, int, int], ramp: float) -> np.ndarray:
    """Partial-volume fraction (z, y, x) of the union of spheres swept along every tube."""
    nz, ny, nx = shape
    voxel = np.array([2.0 / (nx - 1), 2.0 / (ny - 1), 2.0 / (nz - 1)])  # body units per voxel, (x, y, z)
    frac = np.zeros(nz * ny * nx, dtype=np.float32)
    for points, radii in tubes:
        reach = np.ceil((radii.max() + ramp) / voxel).astype(int)
        offsets = np.stack(np.meshgrid(*(np.arange(-r, r + 1) for r in reach), indexing="ij"), -1).reshape(-1, 3)
        for chunk in range(0, len(points), 256):
            p, r = points[chunk:chunk + 256], radii[chunk:chunk + 256]
            centre = (p + 1.0) / voxel  # continuous voxel index (i, j, k)
            idx = np.rint(centre).astype(int)[:, None, :] + offsets[None]
            dist = np.linalg.norm((idx - centre[:, None, :]) * voxel, axis=-1)
            f = np.clip(0.5 + (r[:, None] - dist) / ramp, 0.0, 1.0)
            keep = (f > 0) & np.all((idx >= 0) & (idx < (nx, ny, nz)), axis=-1)
            flat = (idx[..., 2] * ny + idx[..., 1]) * nx + idx[..., 0]
            np.maximum.at(frac, flat[keep], f[keep].astype(np.float32))
    return frac.reshape(shape)
