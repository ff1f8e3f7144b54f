"""RayCaster: one object per volume + transfer function that turns a camera into a FeatureFrame."""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from volsr_core.render import layout as L
from volsr_core.render.classification import ClassificationTables, block_min_max, build_tables, empty_blocks
from volsr_core.render.device import is_device_array
from volsr_core.render.features import FeatureFrame
from volsr_core.scene.camera import Camera
from volsr_core.scene.transfer_function import TransferFunction
from volsr_core.scene.volume import Volume

DEVICES = ("cpu", "cuda")
MOTION_DEPTHS = ("max_alpha", "threshold", "mean")  # P_DEPTH_MODE 0, 1, 2
START_JITTERS = {False: 0.0, True: 1.0, "hash": 1.0, "ign": 2.0}  # P_START_JITTER


def _checked_height(width: int, height: int | None) -> int:
    """``height`` (``width`` when None), after checking that both are positive."""
    height = width if height is None else height
    if width < 1 or height < 1:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    return height


class RayCaster:
    """Direct volume rendering by ray casting, emitting colour and feature buffers in one pass.

    Per pixel a ray through the pixel centre plus the frame's jitter is clipped to the camera's
    near/far planes and to the volume's oriented box (voxel centres); samples lie
    ``sample_distance`` mm apart (default: half the smallest spacing), are interpolated
    trilinearly, classified by the transfer function (opacity corrected for the step), shaded
    with Blinn-Phong and a headlight when the transfer function says so, and composited front
    to back until the accumulated alpha reaches ``early_termination``. Bricks of ``block_size``
    voxels that the transfer function makes fully transparent are skipped.

    ``start_jitter`` offsets each ray's first sample by a fraction of the step, per pixel and per
    ``seed`` (give each frame, or each sample of a supersampled pixel, its own): ``True``/``"hash"``
    a hashed white-noise fraction, ``"ign"`` interleaved gradient noise (Jimenez 2014) shifted per
    seed. It turns the rings of a fixed ray start ("wood grain") into noise that averaging removes.

    Motion vectors reproject one point per ray, chosen by ``motion_depth`` (docs/temporal.md):
    ``"threshold"`` (default) where the accumulated opacity first reaches ``depth_threshold`` (the
    sample of maximum alpha where it never does), ``"max_alpha"`` the sample of maximum alpha (the
    seed paper's choice; it is also always the ``depth`` and ``position`` features), ``"mean"`` the
    opacity-weighted mean of the composited samples' distances. That point's quasi-depth is the
    ``motion_depth`` buffer.

    ``render(..., slabs=K)`` also cuts each ray into K depth slabs (equal spans of view depth over what
    the transfer function shows, :meth:`visible_bounds`, within the clipping range) and composites each
    apart in the same pass: :attr:`FeatureFrame.slabs`, which composited front to back give the frame's
    colour and alpha. An opaque slab ends there, not the ray: the slabs behind keep what it hides.

    ``device="cuda"`` runs the same ray program through numba-cuda (or its simulator).
    """

    def __init__(self, volume: Volume, transfer_function: TransferFunction, *,
                 sample_distance: float | None = None, early_termination: float = 0.99,
                 empty_space_skipping: bool = True, block_size: int = 8,
                 background: Sequence[float] = (0.0, 0.0, 0.0), start_jitter: bool | str = False,
                 device: str = "cpu", lut_size: int = 4096, motion_depth: str = "threshold",
                 depth_threshold: float = 0.5):
        if device not in DEVICES:
            raise ValueError(f"device must be one of {DEVICES}, got {device!r}")
        if not 0.0 < early_termination <= 1.0:
            raise ValueError("early_termination must lie in (0, 1]")
        self.volume = volume
        self.sample_distance = float(sample_distance or 0.5 * min(volume.spacing))
        if self.sample_distance <= 0:
            raise ValueError("sample_distance must be positive")
        self.early_termination = float(early_termination)
        self.empty_space_skipping = bool(empty_space_skipping)
        self.block_size = int(block_size)
        self.background = tuple(float(c) for c in background)
        if start_jitter not in START_JITTERS:
            raise ValueError(f"start_jitter must be False, True, 'hash' or 'ign', got {start_jitter!r}")
        self.start_jitter = start_jitter
        if motion_depth not in MOTION_DEPTHS:
            raise ValueError(f"motion_depth must be one of {MOTION_DEPTHS}, got {motion_depth!r}")
        if not 0.0 < depth_threshold <= 1.0:
            raise ValueError(f"depth_threshold must lie in (0, 1], got {depth_threshold}")
        self.motion_depth, self.depth_threshold = motion_depth, float(depth_threshold)
        self.device = device
        self.lut_size = int(lut_size)
        self._block_lo, self._block_hi = block_min_max(volume.array, self.block_size)
        m = volume.direction @ np.diag(volume.spacing)
        self._w2i = np.ascontiguousarray(volume.world_to_index[:3, :], dtype=np.float64)
        self._grad_w = np.ascontiguousarray(np.linalg.inv(m).T, dtype=np.float64)
        corners = volume.corners
        self._sphere_center = corners.mean(axis=0)
        self._sphere_radius = 0.5 * float(np.linalg.norm(corners.max(axis=0) - corners.min(axis=0)))
        self._cuda_volume = None
        if device == "cuda":
            from volsr_core.render.cuda import CudaVolume
            self._cuda_volume = CudaVolume(volume.array)
        self.transfer_function = transfer_function

    @property
    def transfer_function(self) -> TransferFunction:
        return self._tf

    @transfer_function.setter
    def transfer_function(self, tf: TransferFunction) -> None:
        """Set the transfer function: rebuilds the LUTs and the empty-brick mask (milliseconds)."""
        self._tf = tf
        self.tables: ClassificationTables = build_tables(tf, self.volume.value_range, self.sample_distance,
                                                         self.lut_size)
        if self.empty_space_skipping:
            self._empty = empty_blocks(self._block_lo, self._block_hi, self.tables)
        else:
            self._empty = np.zeros(self._block_lo.shape, dtype=np.uint8)
        b = np.asarray(self.visible_bounds(), dtype=np.float64).reshape(3, 2)
        self._visible_corners = np.array([[x, y, z] for x in b[0] for y in b[1] for z in b[2]])

    def visible_bounds(self) -> tuple[float, float, float, float, float, float]:
        """Axis-aligned world bounds (mm, LPS; as :attr:`Volume.bounds`) of what the transfer function
        shows: the bricks empty-space skipping does not skip, clipped to the volume's box; the whole
        box when everything is transparent. Framing these fills the view with the visible volume."""
        nonempty = np.argwhere(empty_blocks(self._block_lo, self._block_hi, self.tables) == 0)
        if len(nonempty) == 0:
            return self.volume.bounds
        nx, ny, nz = self.volume.shape_xyz
        lo = np.minimum(nonempty.min(axis=0)[::-1] * self.block_size, [nx - 1, ny - 1, nz - 1])  # (i, j, k)
        hi = np.minimum((nonempty.max(axis=0)[::-1] + 1) * self.block_size, [nx - 1, ny - 1, nz - 1])
        corners = np.array([[i, j, k, 1.0] for i in (lo[0], hi[0]) for j in (lo[1], hi[1]) for k in (lo[2], hi[2])])
        world = (corners @ self.volume.index_to_world.T)[:, :3]
        a, b = world.min(axis=0), world.max(axis=0)
        return (a[0], b[0], a[1], b[1], a[2], b[2])

    def _params(self, seed: int, has_prev: bool, slabs: int = 0) -> np.ndarray:
        tf, t = self._tf, self.tables
        p = np.zeros(L.P_SIZE)
        p[L.P_STEP] = self.sample_distance
        p[L.P_ERT] = self.early_termination
        p[L.P_AMBIENT], p[L.P_DIFFUSE] = tf.ambient, tf.diffuse
        p[L.P_SPECULAR], p[L.P_SPEC_POWER] = tf.specular, tf.specular_power
        p[L.P_SHADE] = float(tf.shade)
        p[L.P_GRAD_OPACITY] = float(t.uses_gradient_opacity)
        p[L.P_LUT_X0], p[L.P_LUT_INV_DX] = t.x0, t.inv_dx
        p[L.P_GLUT_INV_DX] = t.gradient_inv_dx
        p[L.P_BG_R:L.P_BG_B + 1] = self.background
        p[L.P_START_JITTER] = START_JITTERS[self.start_jitter]
        p[L.P_SEED] = float(seed % 2**31)
        p[L.P_BLOCK] = float(self.block_size)
        p[L.P_HAS_PREV] = float(has_prev)
        p[L.P_DEPTH_MODE] = float(MOTION_DEPTHS.index(self.motion_depth))
        p[L.P_DEPTH_THRESHOLD] = self.depth_threshold
        p[L.P_SLABS] = float(slabs)
        return p

    def _camera_array(self, camera: Camera, width: int, height: int, jitter: tuple[float, float]) -> np.ndarray:
        right, up, forward = camera.basis()
        c = np.zeros(L.CAM_SIZE)
        c[L.CAM_POS:L.CAM_POS + 3] = camera.position
        c[L.CAM_RIGHT:L.CAM_RIGHT + 3] = right
        c[L.CAM_UP:L.CAM_UP + 3] = up
        c[L.CAM_FWD:L.CAM_FWD + 3] = forward
        half_h = camera.parallel_scale if camera.parallel_projection else math.tan(math.radians(camera.view_angle) / 2)
        c[L.CAM_HALF_W], c[L.CAM_HALF_H] = half_h * width / height, half_h
        c[L.CAM_PARALLEL] = float(camera.parallel_projection)
        c[L.CAM_NEAR], c[L.CAM_FAR] = camera.clipping_range
        c[L.CAM_JITTER_X], c[L.CAM_JITTER_Y] = jitter
        center_depth = float((self._sphere_center - camera.position) @ forward)
        c[L.CAM_DEPTH_LO] = center_depth - self._sphere_radius
        c[L.CAM_DEPTH_SPAN] = 2.0 * self._sphere_radius
        c[L.CAM_FOCAL_DEPTH] = float((camera.focal_point - camera.position) @ forward)
        depths = (self._visible_corners - camera.position) @ forward
        near = max(float(depths.min()), camera.clipping_range[0])
        far = max(min(float(depths.max()), camera.clipping_range[1]), near + 1e-6)
        c[L.CAM_SLAB_NEAR], c[L.CAM_SLAB_SPAN] = near, far - near
        return c

    def render_color(self, camera: Camera, width: int, height: int | None = None, *,
                     jitter: Sequence[float] = (0.0, 0.0), seed: int = 0, out: np.ndarray | None = None,
                     on_device: bool = False) -> np.ndarray:
        """The (H, W, 3) float32 colour of :meth:`render` alone (the same values), from the colour-only ray program:
        no feature tracking per sample (1-2% of the ray march on the CPU) and, on CUDA, only RGB copied back. What
        native rendering and its reduced sizes need; ``out`` may pass an (H, W, 3) float32 array to reuse (a device
        array with ``on_device``). ``on_device`` (device "cuda" only) leaves the image on the GPU, ready when this
        returns."""
        height = _checked_height(width, height)
        self._check_on_device(on_device)
        if (out is None or out.shape != (height, width, 3) or out.dtype != np.float32
                or is_device_array(out) != on_device):
            out = self._new_buffer((height, width, 3), on_device)
        self._cast(camera, width, height, (float(jitter[0]), float(jitter[1])), None, seed, out, 0)
        return out

    def _check_on_device(self, on_device: bool) -> None:
        if on_device and self.device != "cuda":
            raise ValueError(f"on_device needs the cuda device, this ray caster renders on {self.device}")

    @staticmethod
    def _new_buffer(shape: tuple[int, ...], on_device: bool):
        """An uninitialised float32 array of ``shape``: on the GPU (numba's device array) or in host memory."""
        if on_device:
            from numba import cuda
            return cuda.device_array(shape, dtype=np.float32)
        return np.empty(shape, dtype=np.float32)

    def render(self, camera: Camera, width: int, height: int | None = None, *,
               jitter: Sequence[float] = (0.0, 0.0), previous_camera: Camera | None = None,
               seed: int = 0, out: np.ndarray | None = None, slabs: int = 0, on_device: bool = False) -> FeatureFrame:
        """Render ``width`` x ``height`` pixels (height defaults to width) seen by ``camera``.

        ``jitter`` shifts every ray by (jx, jy) pixels (+y down), e.g. a Halton offset in
        [-0.5, 0.5); ``previous_camera`` enables motion vectors; ``seed`` drives the per-ray
        start jitter when it is on; ``out`` may pass a float32 (H, W, OUT_CHANNELS) array to reuse; ``slabs``
        K > 0 also composites K depth slabs apart (:attr:`FeatureFrame.slabs`). ``on_device`` (device "cuda"
        only) leaves the buffers on the GPU: the frame's arrays are device arrays, for kernels that run there
        (:meth:`FeatureFrame.to_host` copies them back).
        """
        height = _checked_height(width, height)
        if slabs < 0 or int(slabs) != slabs:
            raise ValueError(f"slabs must be a whole number >= 0, got {slabs}")
        self._check_on_device(on_device)
        jitter = (float(jitter[0]), float(jitter[1]))
        # on the device always a new buffer: an upscaler there holds the last frame's
        if on_device or out is None or out.shape != (height, width, L.OUT_CHANNELS) or out.dtype != np.float32:
            out = self._new_buffer((height, width, L.OUT_CHANNELS), on_device)
        slab_out = self._cast(camera, width, height, jitter, previous_camera, seed, out, int(slabs))
        return FeatureFrame(out, camera, jitter, previous_camera, self.pixels_per_voxel(camera, height),
                            slab_out if slabs else None)

    def pixels_per_voxel(self, camera: Camera, height: int) -> float:
        """How many pixels of an image ``height`` pixels tall the volume's smallest voxel spacing spans at the focal
        point of ``camera``: how finely a frame of that size samples the volume's detail."""
        return float(min(self.volume.spacing)) / camera.pixel_size_at_focus(height)

    def _cast(self, camera: Camera, width: int, height: int, jitter: tuple[float, float],
              previous_camera: Camera | None, seed: int, out: np.ndarray, slabs: int) -> np.ndarray:
        """Run the kernel of ``out``'s layout (OUT_CHANNELS: every feature; 3: the colour alone) on this caster's
        device; returns the slabs array (a 1x1x1 dummy when ``slabs`` is 0; a device array where ``out`` is one)."""
        cam = self._camera_array(camera, width, height, jitter)
        prev_vp = np.eye(4) if previous_camera is None else previous_camera.view_projection(width / height)
        params = self._params(seed, previous_camera is not None, slabs)
        slab_shape = (slabs, height, width, L.SLAB_CHANNELS) if slabs else (1, 1, 1, L.SLAB_CHANNELS)
        slab_out = self._new_buffer(slab_shape, is_device_array(out))  # a device out: the slabs stay there too
        t = self.tables
        if self.device == "cuda":
            from volsr_core.render.cuda import render_cuda
            self._cuda_volume.set_empty(self._empty)
            render_cuda(self._cuda_volume, t.rgba, t.gradient_opacity, cam, self._w2i, self._grad_w, params,
                        np.ascontiguousarray(prev_vp), out, slab_out)
        else:
            from volsr_core.render.cpu import render_cpu
            render_cpu(self.volume.array, self._empty, t.rgba, t.gradient_opacity, cam, self._w2i, self._grad_w,
                       params, np.ascontiguousarray(prev_vp), out, slab_out)
        return slab_out
