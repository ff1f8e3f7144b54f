"""Transfer function -> lookup tables the kernels read, and empty-space-skipping blocks.

The scalar LUT spans the volume's value range with ``size`` entries; its alpha is already
corrected for the sample distance: ``a' = 1 - (1 - a) ** (step / unit_distance)``, as VTK does.
"""
from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from volsr_core.scene.transfer_function import TransferFunction


@dataclass(frozen=True)
class ClassificationTables:
    """LUTs for one transfer function, value range and sample distance."""

    rgba: np.ndarray            # (n, 4) float32: RGB in [0, 1], step-corrected alpha
    x0: float                   # value of entry 0
    inv_dx: float               # entries per value unit
    gradient_opacity: np.ndarray  # (m,) float32 factor over gradient magnitude
    gradient_inv_dx: float      # entries per (value unit / mm)
    uses_gradient_opacity: bool


def corrected_alpha(alpha: np.ndarray, step: float, unit_distance: float) -> np.ndarray:
    """Opacity of one sample ``step`` mm long, given opacity per ``unit_distance`` mm."""
    a = np.clip(np.asarray(alpha, dtype=np.float64), 0.0, 1.0)
    return 1.0 - np.power(1.0 - a, step / unit_distance)


def build_tables(tf: TransferFunction, value_range: tuple[float, float], step: float,
                 size: int = 4096, gradient_size: int = 1024) -> ClassificationTables:
    """Sample ``tf`` on ``value_range`` for samples ``step`` mm apart."""
    lo, hi = float(value_range[0]), float(value_range[1])
    if hi <= lo:
        hi = lo + 1.0
    xs = np.linspace(lo, hi, size)
    rgba = np.empty((size, 4), dtype=np.float32)
    rgba[:, :3] = np.clip(tf.color_at(xs), 0.0, 1.0)
    rgba[:, 3] = corrected_alpha(tf.opacity_at(xs), step, tf.scalar_opacity_unit_distance)
    if tf.has_gradient_opacity:
        g_hi = max(float(tf.gradient_opacity[-1, 0]), 1e-6)
        gs = np.linspace(0.0, g_hi, gradient_size)
        gop = np.clip(tf.gradient_opacity_at(gs), 0.0, 1.0).astype(np.float32)
        g_inv = (gradient_size - 1) / g_hi
    else:
        gop, g_inv = np.ones(2, dtype=np.float32), 0.0
    return ClassificationTables(rgba, lo, (size - 1) / (hi - lo), gop, g_inv, tf.has_gradient_opacity)


@numba.njit(parallel=True, cache=True)
def block_min_max(vol: np.ndarray, block: int) -> tuple[np.ndarray, np.ndarray]:
    """Min and max of each ``block``-voxel brick, bricks overlapping by one voxel.

    Brick b covers voxel indices [b*block, (b+1)*block] along each axis: every voxel that a
    trilinear sample at an index position inside the brick reads. Shapes (ceil((n-1)/block), ...).
    """
    nz, ny, nx = vol.shape
    bz = max((nz - 2) // block + 1, 1)
    by = max((ny - 2) // block + 1, 1)
    bx = max((nx - 2) // block + 1, 1)
    lo = np.empty((bz, by, bx), dtype=np.float32)
    hi = np.empty((bz, by, bx), dtype=np.float32)
    for kb in numba.prange(bz):
        for jb in range(by):
            for ib in range(bx):
                vmin = np.inf
                vmax = -np.inf
                for k in range(kb * block, min((kb + 1) * block + 1, nz)):
                    for j in range(jb * block, min((jb + 1) * block + 1, ny)):
                        for i in range(ib * block, min((ib + 1) * block + 1, nx)):
                            v = vol[k, j, i]
                            vmin = min(vmin, v)
                            vmax = max(vmax, v)
                lo[kb, jb, ib] = vmin
                hi[kb, jb, ib] = vmax
    return lo, hi


def empty_blocks(block_lo: np.ndarray, block_hi: np.ndarray, tables: ClassificationTables) -> np.ndarray:
    """uint8 mask of bricks where every value in [min, max] classifies to alpha 0."""
    n = tables.rgba.shape[0]
    visible = np.concatenate([[0], np.cumsum(tables.rgba[:, 3] > 0.0)])  # visible[i] = #nonzero in [0, i)
    i0 = np.clip(np.floor((block_lo - tables.x0) * tables.inv_dx), 0, n - 1).astype(np.int64)
    i1 = np.clip(np.ceil((block_hi - tables.x0) * tables.inv_dx), 0, n - 1).astype(np.int64)
    return ((visible[i1 + 1] - visible[i0]) == 0).astype(np.uint8)
