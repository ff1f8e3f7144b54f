"""The ray loop, cut into named stages like VTK's raycasterfs.glsl, written once for CPU and CUDA.

:func:`build_ray_program` takes a decorator (``numba.njit(inline="always")`` for the CPU,
``numba.cuda.jit(device=True)`` for CUDA) and returns ``march_ray``, the per-pixel program: a
short list of stage calls, each stage a small function compiled with the same decorator. Only
scalar maths, ``math`` functions and array indexing appear here, and stages return scalars or
tuples of scalars, so the same source compiles for both targets.

Stages, per ray:

- ``camera_ray``: world ray through the pixel centre plus the frame's jitter;
- ``index_ray``: the same ray in continuous voxel index space;
- ``plane_crossings``: ray parameters of the near, far and focal planes;
- ``ray_interval``: first sample and sample count: [near, far] clipped to the volume box, the
  start offset by the per-ray start jitter when it is on;

then per sample k, at ``t = t0 + k * step``:

- ``sample_position``: index-space position of the sample;
- ``skip_empty``: the next sample past a transparent block (empty-space skipping), else k;
- ``sample``: trilinear interpolation;
- ``classify``: RGBA from the transfer-function LUT, opacity already corrected for the step;

and for a visible sample (alpha > 0):

- ``gradient``: central differences, world units; only where ``needs_gradient`` (shading or
  gradient opacity on);
- ``shade``: gradient opacity and Blinn-Phong headlight, each when on;
- ``track_max_alpha``: RGBA and ray parameter of the most opaque sample so far;
- ``composite``: front to back;
- ``track_motion_point``: where the accumulated opacity crosses the depth threshold, and the
  opacity-weighted sum of the samples' depths;
- ``slab_index`` and ``store_slab`` (when the frame asks for depth slabs, ``P_SLABS`` > 0): the same
  samples composited apart per depth slab, each slab's partial composite and motion vector stored
  as the ray leaves it; an opaque slab skips to the next (``next_slab_sample``) instead of ending the ray,
  and behind an opaque front the hidden slabs are sampled every ``HIDDEN_STRIDE``-th step;
- ``terminated``: early ray termination (with slabs, per slab);

and last ``motion_point`` (the point motion vectors reproject: max alpha, opacity threshold or
opacity-weighted mean) and ``finish``: background, features at the sample of maximum alpha,
quasi-depths, motion vector. The colour-only program (``build_ray_program(jit, features=False)``, what
native rendering runs) skips the two tracking stages and ends in ``finish_color``.

On the CPU numba inlines every stage (``inline="always"``), and each inlined call that takes an
array holds its own reference to it. Stages therefore read their arrays before they branch: numba
then prunes that reference counting. An array still referenced after a branch inside a stage
costs atomic reference-count updates each time the stage runs (measured: 5-7% slower at 512²
when ``shade`` did so, once per visible sample).

Geometry: ``w2i`` (3x4) maps world mm to continuous voxel index (i, j, k) = (x, y, z); the volume
box is [0, n-1] per axis (voxel centres), ``vol[k, j, i]``. ``grad_w`` (3x3) maps an index-space
gradient to a world gradient (value units per mm). The ray parameter ``t`` is in world mm along
the unit world direction, in world and index space alike: p(t) = o + t d.
"""
from __future__ import annotations

import math
from typing import Callable

from volsr_core.render.layout import (
    CAM_DEPTH_LO, CAM_DEPTH_SPAN, CAM_FAR, CAM_FOCAL_DEPTH, CAM_FWD, CAM_HALF_H, CAM_HALF_W, CAM_JITTER_X, CAM_JITTER_Y,
    CAM_NEAR, CAM_PARALLEL, CAM_POS, CAM_RIGHT, CAM_SLAB_NEAR, CAM_SLAB_SPAN, CAM_UP, OUT_ALPHA, OUT_COLOR, OUT_DEPTH,
    OUT_MAX_RGBA, OUT_MOTION, OUT_MOTION_DEPTH, OUT_POSITION, P_AMBIENT, P_BG_B, P_BG_G, P_BG_R, P_BLOCK, P_DEPTH_MODE,
    P_DEPTH_THRESHOLD, P_DIFFUSE, P_ERT, P_GLUT_INV_DX, P_GRAD_OPACITY, P_HAS_PREV, P_LUT_INV_DX, P_LUT_X0, P_SEED,
    P_SHADE, P_SLABS, P_SPEC_POWER, P_SPECULAR, P_START_JITTER, P_STEP, SLAB_CHANNELS, SLAB_MOTION, SLAB_RGBA,
)


# Behind an opaque front (accumulated alpha past early termination) the slabs it hides are sampled every
# HIDDEN_STRIDE-th step, the opacity corrected for the longer step: they only feed the layered TAAU's history
# of what may show next, and 4 cut their render time by half or more at no measured cost (docs/renderer.md).
HIDDEN_STRIDE = 4


def build_ray_program(jit: Callable, features: bool = True) -> Callable:
    """Compile the stages with ``jit`` and return ``march_ray(x, y, vol, empty, lut, glut, cam, w2i,
    grad_w, params, prev_vp, out, slabs)``, which renders pixel (x, y) into ``out[y, x, :]`` and, when
    ``params[P_SLABS]`` > 0, its depth slabs into ``slabs[:, y, x, :]``.

    ``features=False`` builds the colour-only program: no feature tracking per sample (``track_max_alpha``,
    ``track_motion_point``) and ``finish_color`` in place of ``finish``, into an ``out`` of 3 channels (RGB over
    the background); the same colours, 1-2% less time (a ray-march cost the native renderings need not pay)."""

    # ray setup ----------------------------------------------------------------------------------
    @jit
    def hash_unit(x, y, seed):
        """A deterministic pseudo-random number in [0, 1) from a pixel and a seed (PCG-style hash)."""
        h = (x * 73856093 + y * 19349663 + seed * 83492791 + 12345) & 0xFFFFFFFF
        h = ((h ^ (h >> 16)) * 0x45D9F3B) & 0xFFFFFFFF
        h = ((h ^ (h >> 16)) * 0x45D9F3B) & 0xFFFFFFFF
        h = h ^ (h >> 16)
        return (h & 0xFFFFFF) / 16777216.0

    @jit
    def ign_unit(x, y, seed):
        """Interleaved gradient noise (Jimenez 2014) in [0, 1) at pixel (x, y), shifted per frame (``seed``):
        neighbouring pixels get well-spread offsets, so a temporal filter averages them quickly."""
        shift = 5.588238 * (seed % 64)
        f = 0.06711056 * (x + shift) + 0.00583715 * (y + shift)
        f = 52.9829189 * (f - math.floor(f))
        return f - math.floor(f)

    @jit
    def camera_ray(x, y, width, height, cam):
        """Stage: world origin and unit direction of the ray through pixel (x, y) plus the camera jitter."""
        nx = 2.0 * (x + 0.5 + cam[CAM_JITTER_X]) / width - 1.0
        ny = 1.0 - 2.0 * (y + 0.5 + cam[CAM_JITTER_Y]) / height
        sx = nx * cam[CAM_HALF_W]
        sy = ny * cam[CAM_HALF_H]
        if cam[CAM_PARALLEL] > 0.5:
            ox = cam[CAM_POS] + sx * cam[CAM_RIGHT] + sy * cam[CAM_UP]
            oy = cam[CAM_POS + 1] + sx * cam[CAM_RIGHT + 1] + sy * cam[CAM_UP + 1]
            oz = cam[CAM_POS + 2] + sx * cam[CAM_RIGHT + 2] + sy * cam[CAM_UP + 2]
            return ox, oy, oz, cam[CAM_FWD], cam[CAM_FWD + 1], cam[CAM_FWD + 2]
        dx = cam[CAM_FWD] + sx * cam[CAM_RIGHT] + sy * cam[CAM_UP]
        dy = cam[CAM_FWD + 1] + sx * cam[CAM_RIGHT + 1] + sy * cam[CAM_UP + 1]
        dz = cam[CAM_FWD + 2] + sx * cam[CAM_RIGHT + 2] + sy * cam[CAM_UP + 2]
        inv = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
        return cam[CAM_POS], cam[CAM_POS + 1], cam[CAM_POS + 2], dx * inv, dy * inv, dz * inv

    @jit
    def index_ray(ox, oy, oz, dx, dy, dz, w2i):
        """Stage: the world ray in continuous voxel index space; t keeps its meaning (mm along the world ray)."""
        oi = w2i[0, 0] * ox + w2i[0, 1] * oy + w2i[0, 2] * oz + w2i[0, 3]
        oj = w2i[1, 0] * ox + w2i[1, 1] * oy + w2i[1, 2] * oz + w2i[1, 3]
        ok = w2i[2, 0] * ox + w2i[2, 1] * oy + w2i[2, 2] * oz + w2i[2, 3]
        di = w2i[0, 0] * dx + w2i[0, 1] * dy + w2i[0, 2] * dz
        dj = w2i[1, 0] * dx + w2i[1, 1] * dy + w2i[1, 2] * dz
        dk = w2i[2, 0] * dx + w2i[2, 1] * dy + w2i[2, 2] * dz
        return oi, oj, ok, di, dj, dk

    @jit
    def plane_crossings(dx, dy, dz, cam):
        """Stage: ray parameters where the ray crosses the near, far and focal planes (view depths)."""
        near = cam[CAM_NEAR]
        far = cam[CAM_FAR]
        focal = cam[CAM_FOCAL_DEPTH]
        cosv = dx * cam[CAM_FWD] + dy * cam[CAM_FWD + 1] + dz * cam[CAM_FWD + 2]
        if cam[CAM_PARALLEL] > 0.5:
            return near, far, focal
        return near / cosv, far / cosv, focal / cosv

    @jit
    def clip_slab(o, d, hi, t0, t1):
        """Clip the interval [t0, t1] of o + t d to the slab 0 <= coordinate <= hi."""
        if abs(d) < 1e-12:
            if o < 0.0 or o > hi:
                return 1.0, 0.0
            return t0, t1
        a = (0.0 - o) / d
        b = (hi - o) / d
        if a > b:
            a, b = b, a
        return max(t0, a), min(t1, b)

    @jit
    def ray_interval(x, y, oi, oj, ok, di, dj, dk, t_near, t_far, vol, params):
        """Stage: (t0, n_steps), the first sample's ray parameter and the number of samples.

        [t_near, t_far] is clipped to the volume box (voxel centres); with start jitter on, t0 moves
        forward by a per-pixel, per-seed fraction of a step (``P_START_JITTER`` 1: white-noise hash, 2:
        interleaved gradient noise). n_steps is 0 for a ray that misses the box.
        """
        nz, ny, nx = vol.shape
        step = params[P_STEP]
        start_jitter = params[P_START_JITTER]
        seed = int(params[P_SEED])
        t0, t1 = clip_slab(oi, di, nx - 1.0, t_near, t_far)
        t0, t1 = clip_slab(oj, dj, ny - 1.0, t0, t1)
        t0, t1 = clip_slab(ok, dk, nz - 1.0, t0, t1)
        if t0 > t1:
            return t0, 0
        if start_jitter > 1.5:
            t0 += step * ign_unit(x, y, seed)
        elif start_jitter > 0.5:
            t0 += step * hash_unit(x, y, seed)
        return t0, int(math.floor((t1 - t0) / step)) + 1

    # per sample ---------------------------------------------------------------------------------
    @jit
    def sample_position(t, oi, oj, ok, di, dj, dk):
        """Stage: index-space position of the sample at ray parameter t."""
        return oi + t * di, oj + t * dj, ok + t * dk

    @jit
    def block_exit(px, py, pz, dx, dy, dz, block, t):
        """Ray parameter where the ray at index position p (parameter t) leaves its block."""
        best = 1e30
        if dx > 1e-12:
            best = min(best, ((math.floor(px / block) + 1.0) * block - px) / dx)
        elif dx < -1e-12:
            best = min(best, (math.floor(px / block) * block - px) / dx)
        if dy > 1e-12:
            best = min(best, ((math.floor(py / block) + 1.0) * block - py) / dy)
        elif dy < -1e-12:
            best = min(best, (math.floor(py / block) * block - py) / dy)
        if dz > 1e-12:
            best = min(best, ((math.floor(pz / block) + 1.0) * block - pz) / dz)
        elif dz < -1e-12:
            best = min(best, (math.floor(pz / block) * block - pz) / dz)
        return t + best

    @jit
    def skip_empty(k, t, t0, px, py, pz, di, dj, dk, empty, params):
        """Stage: index of the next sample to take; k itself unless sample k lies in a transparent block,
        else the first sample (on the same grid) past that block."""
        block = params[P_BLOCK]
        step = params[P_STEP]
        bi = int(max(px, 0.0) / block)
        bj = int(max(py, 0.0) / block)
        bk = int(max(pz, 0.0) / block)
        if empty[min(bk, empty.shape[0] - 1), min(bj, empty.shape[1] - 1), min(bi, empty.shape[2] - 1)]:
            t_exit = block_exit(px, py, pz, di, dj, dk, block, t)
            k_next = int(math.ceil((t_exit - t0) / step - 1e-9))
            return max(k_next, k + 1)
        return k

    @jit
    def sample(vol, px, py, pz):
        """Stage: trilinear interpolation of vol[k, j, i] at continuous index (px, py, pz), clamped to the box."""
        nz, ny, nx = vol.shape
        px = min(max(px, 0.0), nx - 1.0)
        py = min(max(py, 0.0), ny - 1.0)
        pz = min(max(pz, 0.0), nz - 1.0)
        i = min(int(px), nx - 2)
        j = min(int(py), ny - 2)
        k = min(int(pz), nz - 2)
        fx, fy, fz = px - i, py - j, pz - k
        c00 = vol[k, j, i] * (1.0 - fx) + vol[k, j, i + 1] * fx
        c10 = vol[k, j + 1, i] * (1.0 - fx) + vol[k, j + 1, i + 1] * fx
        c01 = vol[k + 1, j, i] * (1.0 - fx) + vol[k + 1, j, i + 1] * fx
        c11 = vol[k + 1, j + 1, i] * (1.0 - fx) + vol[k + 1, j + 1, i + 1] * fx
        c0 = c00 * (1.0 - fy) + c10 * fy
        c1 = c01 * (1.0 - fy) + c11 * fy
        return c0 * (1.0 - fz) + c1 * fz

    @jit
    def classify(value, lut, params):
        """Stage: RGBA from the transfer-function LUT (linear between entries; alpha corrected for the step)."""
        n = lut.shape[0]
        f = (value - params[P_LUT_X0]) * params[P_LUT_INV_DX]
        f = min(max(f, 0.0), n - 1.0)
        i = min(int(f), n - 2)
        w = f - i
        r = lut[i, 0] * (1.0 - w) + lut[i + 1, 0] * w
        g = lut[i, 1] * (1.0 - w) + lut[i + 1, 1] * w
        b = lut[i, 2] * (1.0 - w) + lut[i + 1, 2] * w
        a = lut[i, 3] * (1.0 - w) + lut[i + 1, 3] * w
        return r, g, b, a

    @jit
    def gradient(vol, px, py, pz, grad_w):
        """Stage: world-space gradient (value units per mm) by central differences one voxel apart."""
        gi = 0.5 * (sample(vol, px + 1.0, py, pz) - sample(vol, px - 1.0, py, pz))
        gj = 0.5 * (sample(vol, px, py + 1.0, pz) - sample(vol, px, py - 1.0, pz))
        gk = 0.5 * (sample(vol, px, py, pz + 1.0) - sample(vol, px, py, pz - 1.0))
        gx = grad_w[0, 0] * gi + grad_w[0, 1] * gj + grad_w[0, 2] * gk
        gy = grad_w[1, 0] * gi + grad_w[1, 1] * gj + grad_w[1, 2] * gk
        gz = grad_w[2, 0] * gi + grad_w[2, 1] * gj + grad_w[2, 2] * gk
        return gx, gy, gz

    @jit
    def gradient_opacity(magnitude, glut, params):
        """Gradient-opacity factor from its LUT (linear between entries, clamped)."""
        n = glut.shape[0]
        f = min(max(magnitude * params[P_GLUT_INV_DX], 0.0), n - 1.0)
        i = min(int(f), n - 2)
        w = f - i
        return glut[i] * (1.0 - w) + glut[i + 1] * w

    @jit
    def blinn_phong(r, g, b, gx, gy, gz, gmag, dx, dy, dz, ambient, diffuse, specular, specular_power):
        """Blinn-Phong with a headlight (light and eye along -ray), two-sided, white light.

        Where the gradient vanishes the sample is lit as if it faced the light.
        """
        ndotl = 1.0
        if gmag > 1e-6:
            ndotl = abs(gx * dx + gy * dy + gz * dz) / gmag
        light = ambient + diffuse * ndotl
        spec = specular * math.pow(ndotl, specular_power)  # half vector = light dir
        return min(r * light + spec, 1.0), min(g * light + spec, 1.0), min(b * light + spec, 1.0)

    @jit
    def needs_gradient(params):
        """Whether shade needs the sample's gradient (lighting or gradient opacity on)."""
        return params[P_SHADE] > 0.5 or params[P_GRAD_OPACITY] > 0.5

    @jit
    def shade(r, g, b, a, gx, gy, gz, dx, dy, dz, glut, params):
        """Stage: RGBA of a classified sample with world gradient (gx, gy, gz) after gradient opacity and
        Blinn-Phong lighting, each when the transfer function turns it on."""
        # params and glut are read before the branches (see the module docstring)
        use_gop = params[P_GRAD_OPACITY] > 0.5
        shading = params[P_SHADE] > 0.5
        ambient = params[P_AMBIENT]
        diffuse = params[P_DIFFUSE]
        specular = params[P_SPECULAR]
        specular_power = params[P_SPEC_POWER]
        gmag = math.sqrt(gx * gx + gy * gy + gz * gz)
        gop = gradient_opacity(gmag, glut, params)  # glut has two entries (ones) when unused
        if use_gop:
            a *= gop
        if shading:
            r, g, b = blinn_phong(r, g, b, gx, gy, gz, gmag, dx, dy, dz, ambient, diffuse, specular, specular_power)
        return r, g, b, a

    @jit
    def track_max_alpha(r, g, b, a, t, mr, mg, mb, ma, t_max):
        """Stage: (mr, mg, mb, ma, t_max), the RGBA and ray parameter of the most opaque sample so far."""
        if a > ma:
            return r, g, b, a, t
        return mr, mg, mb, ma, t_max

    @jit
    def composite(r, g, b, a, cr, cg, cb, ca):
        """Stage: the accumulated premultiplied colour (cr, cg, cb, ca) with a sample behind it (front to back)."""
        w = (1.0 - ca) * a
        return cr + w * r, cg + w * g, cb + w * b, ca + w

    @jit
    def track_motion_point(t, ca_before, ca, t_cross, sum_w, sum_wt, threshold):
        """Stage: (t_cross, sum_w, sum_wt): where the accumulated opacity first reached ``threshold``
        (-1 until it does), and the sums of composited weights and weight * t (their mean depth)."""
        w = ca - ca_before
        if t_cross < 0.0 and ca >= threshold:
            t_cross = t
        return t_cross, sum_w + w, sum_wt + w * t

    @jit
    def motion_point(t_max, t_cross, sum_w, sum_wt, params):
        """Stage: the ray parameter of the point motion vectors reproject (``P_DEPTH_MODE``): 0 the sample of
        maximum alpha, 1 where the accumulated opacity reached ``P_DEPTH_THRESHOLD`` (max alpha where it
        never did), 2 the opacity-weighted mean of the composited samples (max alpha where none was)."""
        mode = params[P_DEPTH_MODE]
        if mode > 1.5 and sum_w > 0.0:
            return sum_wt / sum_w
        if mode > 0.5 and mode < 1.5 and t_cross >= 0.0:
            return t_cross
        return t_max

    @jit
    def slab_mapping(dx, dy, dz, cam, n_slabs):
        """Stage: (rate, offset) with which ``t * rate - offset`` is the slab coordinate of ray parameter t: the
        view depth's position in [CAM_SLAB_NEAR, CAM_SLAB_NEAR + CAM_SLAB_SPAN], in units of one of n_slabs."""
        per_slab = cam[CAM_SLAB_SPAN] / max(n_slabs, 1)
        offset = cam[CAM_SLAB_NEAR]
        rate = 1.0
        if cam[CAM_PARALLEL] < 0.5:  # the ray starts at the eye: view depth = t cos(angle to the view direction)
            rate = dx * cam[CAM_FWD] + dy * cam[CAM_FWD + 1] + dz * cam[CAM_FWD + 2]
        return rate / per_slab, offset / per_slab

    @jit
    def slab_index(t, rate, offset, n_slabs):
        """Stage: the depth slab (0 nearest, n_slabs - 1 farthest; samples beyond either end join it) of the
        sample at ray parameter t."""
        return min(max(int(math.floor(t * rate - offset)), 0), n_slabs - 1)

    @jit
    def store_slab(x, y, slab, sr, sg, sb, sa, sum_w, sum_wt, ox, oy, oz, dx, dy, dz, width, height, cam, params,
                   prev_vp, slabs):
        """Stage: write a slab's partial composite (premultiplied RGBA of its samples alone) and the motion
        vector of its opacity-weighted mean point into ``slabs[slab, y, x]``."""
        t = sum_wt / sum_w if sum_w > 0.0 else 0.0
        mx, my = reproject(ox + t * dx, oy + t * dy, oz + t * dz, x, y, width, height, cam, params, prev_vp)
        slabs[slab, y, x, SLAB_RGBA] = sr
        slabs[slab, y, x, SLAB_RGBA + 1] = sg
        slabs[slab, y, x, SLAB_RGBA + 2] = sb
        slabs[slab, y, x, SLAB_RGBA + 3] = sa
        slabs[slab, y, x, SLAB_MOTION] = mx
        slabs[slab, y, x, SLAB_MOTION + 1] = my

    @jit
    def next_slab_sample(k, slab, rate, offset, t0, step):
        """Stage: the index of the first sample past sample k that lies in a slab behind ``slab``."""
        t_next = (slab + 1 + offset) / rate
        return max(int(math.ceil((t_next - t0) / step - 1e-9)), k + 1)

    @jit
    def clear_slabs(x, y, n_slabs, slabs):
        """Stage: empty every slab of pixel (x, y) before the ray fills those it crosses."""
        for k in range(n_slabs):
            for c in range(SLAB_CHANNELS):
                slabs[k, y, x, c] = 0.0

    @jit
    def terminated(ca, params):
        """Stage: early ray termination, once the accumulated alpha reaches the threshold."""
        return ca >= params[P_ERT]

    # per ray, after the loop --------------------------------------------------------------------
    @jit
    def quasi_depth(wx, wy, wz, cam):
        """View depth of world point w mapped to [0, 1] over the volume's bounding sphere (clamped)."""
        z = ((wx - cam[CAM_POS]) * cam[CAM_FWD] + (wy - cam[CAM_POS + 1]) * cam[CAM_FWD + 1]
             + (wz - cam[CAM_POS + 2]) * cam[CAM_FWD + 2])
        return min(max((z - cam[CAM_DEPTH_LO]) / cam[CAM_DEPTH_SPAN], 0.0), 1.0)

    @jit
    def reproject(rx, ry, rz, x, y, width, height, cam, params, prev_vp):
        """Stage: (mx, my), pixels from pixel (x, y) (plus the jitter) to where world point r lay in the previous
        frame (``prev_vp``); (0, 0) without a previous camera."""
        mx = 0.0
        my = 0.0
        if params[P_HAS_PREV] > 0.5:
            cx = prev_vp[0, 0] * rx + prev_vp[0, 1] * ry + prev_vp[0, 2] * rz + prev_vp[0, 3]
            cy = prev_vp[1, 0] * rx + prev_vp[1, 1] * ry + prev_vp[1, 2] * rz + prev_vp[1, 3]
            cw = prev_vp[3, 0] * rx + prev_vp[3, 1] * ry + prev_vp[3, 2] * rz + prev_vp[3, 3]
            if cw > 1e-12:
                prev_px = (cx / cw + 1.0) * 0.5 * width
                prev_py = (1.0 - cy / cw) * 0.5 * height
                mx = prev_px - (x + 0.5 + cam[CAM_JITTER_X])
                my = prev_py - (y + 0.5 + cam[CAM_JITTER_Y])
        return mx, my

    @jit
    def finish(x, y, width, height, out, cr, cg, cb, ca, mr, mg, mb, ma, wx, wy, wz, rx, ry, rz, cam, params,
               prev_vp):
        """Stage: write colour over the background, the max-alpha features (its world point w: ``position``,
        ``depth``) and, for the point r the motion vector reprojects, ``motion_depth`` and the vector."""
        out[y, x, OUT_COLOR] = cr + (1.0 - ca) * params[P_BG_R]
        out[y, x, OUT_COLOR + 1] = cg + (1.0 - ca) * params[P_BG_G]
        out[y, x, OUT_COLOR + 2] = cb + (1.0 - ca) * params[P_BG_B]
        out[y, x, OUT_ALPHA] = ca
        out[y, x, OUT_MAX_RGBA] = mr
        out[y, x, OUT_MAX_RGBA + 1] = mg
        out[y, x, OUT_MAX_RGBA + 2] = mb
        out[y, x, OUT_MAX_RGBA + 3] = ma
        out[y, x, OUT_POSITION] = wx
        out[y, x, OUT_POSITION + 1] = wy
        out[y, x, OUT_POSITION + 2] = wz
        depth = 1.0
        motion_depth = 1.0
        if ma > 0.0:
            depth = quasi_depth(wx, wy, wz, cam)
            motion_depth = quasi_depth(rx, ry, rz, cam)
        out[y, x, OUT_DEPTH] = depth
        out[y, x, OUT_MOTION_DEPTH] = motion_depth
        mx, my = reproject(rx, ry, rz, x, y, width, height, cam, params, prev_vp)
        out[y, x, OUT_MOTION] = mx
        out[y, x, OUT_MOTION + 1] = my

    @jit
    def finish_color(x, y, out, cr, cg, cb, ca, params):
        """Stage (colour-only program): write the colour over the background."""
        out[y, x, OUT_COLOR] = cr + (1.0 - ca) * params[P_BG_R]
        out[y, x, OUT_COLOR + 1] = cg + (1.0 - ca) * params[P_BG_G]
        out[y, x, OUT_COLOR + 2] = cb + (1.0 - ca) * params[P_BG_B]

    @jit
    def march_ray(x, y, vol, empty, lut, glut, cam, w2i, grad_w, params, prev_vp, out, slabs):
        """Render pixel (x, y): the stages in order."""
        height = out.shape[0]
        width = out.shape[1]
        n_slabs = int(params[P_SLABS])
        ox, oy, oz, dx, dy, dz = camera_ray(x, y, width, height, cam)
        slab_rate, slab_offset = slab_mapping(dx, dy, dz, cam, n_slabs)
        if n_slabs > 0:
            clear_slabs(x, y, n_slabs, slabs)
        slab = -1  # the slab being composited, its premultiplied RGBA and its weighted depth sums
        sr, sg, sb, sa, s_w, s_wt = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        oi, oj, ok, di, dj, dk = index_ray(ox, oy, oz, dx, dy, dz, w2i)
        t_near, t_far, t_focal = plane_crossings(dx, dy, dz, cam)
        t0, n_steps = ray_interval(x, y, oi, oj, ok, di, dj, dk, t_near, t_far, vol, params)
        step = params[P_STEP]
        cr, cg, cb, ca = 0.0, 0.0, 0.0, 0.0  # accumulated colour, premultiplied
        mr, mg, mb, ma = 0.0, 0.0, 0.0, 0.0  # sample of maximum alpha ...
        t_max = t_focal  # ... at t_max; the focal plane when no sample is visible
        threshold = params[P_DEPTH_THRESHOLD]
        t_cross, sum_w, sum_wt = -1.0, 0.0, 0.0  # for the point motion vectors reproject
        k = 0
        stride = 1  # samples per step: HIDDEN_STRIDE once the slabs left to march are hidden
        hidden_stride = HIDDEN_STRIDE if n_slabs > 0 else 1
        ert = params[P_ERT]
        while k < n_steps:
            t = t0 + k * step
            px, py, pz = sample_position(t, oi, oj, ok, di, dj, dk)
            k_next = skip_empty(k, t, t0, px, py, pz, di, dj, dk, empty, params)
            if k_next > k:
                k = k_next
                continue
            value = sample(vol, px, py, pz)
            r, g, b, a = classify(value, lut, params)
            if a > 0.0:
                if needs_gradient(params):
                    gx, gy, gz = gradient(vol, px, py, pz, grad_w)
                    r, g, b, a = shade(r, g, b, a, gx, gy, gz, dx, dy, dz, glut, params)
                if stride > 1:  # a hidden slab's longer step
                    a = 1.0 - (1.0 - a) ** stride
                ca_before = ca
                cr, cg, cb, ca = composite(r, g, b, a, cr, cg, cb, ca)
                # the features see the samples a render without slabs sees: it ends the ray where ca reaches ert, which
                # a ray in slabs passes (at the hidden stride, or after a jump at the full step to its next sample)
                if features and ca_before < ert:
                    mr, mg, mb, ma, t_max = track_max_alpha(r, g, b, a, t, mr, mg, mb, ma, t_max)
                    t_cross, sum_w, sum_wt = track_motion_point(t, ca_before, ca, t_cross, sum_w, sum_wt, threshold)
                if n_slabs > 0:
                    k_slab = slab_index(t, slab_rate, slab_offset, n_slabs)
                    if k_slab != slab:
                        if slab >= 0:
                            store_slab(x, y, slab, sr, sg, sb, sa, s_w, s_wt, ox, oy, oz, dx, dy, dz, width, height,
                                       cam, params, prev_vp, slabs)
                        slab, sr, sg, sb, sa, s_w, s_wt = k_slab, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
                    sa_before = sa
                    sr, sg, sb, sa = composite(r, g, b, a, sr, sg, sb, sa)
                    s_w, s_wt = s_w + (sa - sa_before), s_wt + (sa - sa_before) * t
                    if terminated(sa, params):  # this slab is opaque: on to the next, whose layers it hides
                        if slab == n_slabs - 1:
                            break
                        k = next_slab_sample(k, slab, slab_rate, slab_offset, t0, step)
                        continue
                elif terminated(ca, params):
                    break
            k += stride
            if stride < hidden_stride and ca >= ert:
                stride = hidden_stride
        if slab >= 0:
            store_slab(x, y, slab, sr, sg, sb, sa, s_w, s_wt, ox, oy, oz, dx, dy, dz, width, height, cam, params,
                       prev_vp, slabs)
        if not features:
            finish_color(x, y, out, cr, cg, cb, ca, params)
            return
        t_motion = motion_point(t_max, t_cross, sum_w, sum_wt, params)
        finish(x, y, width, height, out, cr, cg, cb, ca, mr, mg, mb, ma,
               ox + t_max * dx, oy + t_max * dy, oz + t_max * dz,
               ox + t_motion * dx, oy + t_motion * dy, oz + t_motion * dz, cam, params, prev_vp)

    return march_ray
