"""FeatureFrame: everything one ray-cast pass emits, float32 (H, W, C), pixel (0, 0) top left."""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from volsr_core.atomic import atomic_write
from volsr_core.images import to_uint8
from volsr_core.render.device import channels
from volsr_core.render.layout import (
    OUT_ALPHA, OUT_CHANNELS, OUT_COLOR, OUT_DEPTH, OUT_MAX_RGBA, OUT_MOTION, OUT_MOTION_DEPTH, OUT_POSITION,
    SLAB_CHANNELS,
)
from volsr_core.scene.camera import Camera


@dataclass
class FeatureFrame:
    """One rendered frame and its feature buffers (views into one packed float32 array).

    - ``color`` (H, W, 3): RGB composited front to back over the background, in [0, 1];
    - ``alpha`` (H, W): accumulated opacity;
    - ``depth`` (H, W): quasi-depth of the sample of maximum alpha, *normalised*: the view-space
      distance along the view direction mapped linearly so that the front of the volume's
      bounding sphere is 0 and its back is 1 (stable while the camera orbits); 1 for background;
    - ``max_rgba`` (H, W, 4): shaded RGB and step-corrected alpha of that sample; 0 for background;
    - ``position`` (H, W, 3): its world position in mm (LPS); background pixels (``max_rgba``
      alpha 0) hold their ray's point on the focal plane;
    - ``motion`` (H, W, 2): pixels from the current pixel to where the ray's reprojected point was in the
      previous frame, (dx, dy) with +y down, jitter excluded: ``prev[y + dy, x + dx]``
      backward-warps. Zero when no previous camera was given. The point reprojected is the one
      ``RayCaster.motion_depth`` chooses (where the opacity reaches 0.5, by default);
    - ``motion_depth`` (H, W): quasi-depth (as ``depth``) of that point; 1 for background;
    - ``jitter``: the sub-pixel offset (pixels, +y down) every ray was shifted by;
    - ``pixels_per_voxel``: how many of this frame's pixels the volume's smallest voxel spacing spans
      at the focal point (None when unknown): how finely the frame samples the volume's detail;
    - ``slabs`` (K, H, W, SLAB_CHANNELS) or None: the frame cut into K depth slabs, nearest first
      (``RayCaster.render(..., slabs=K)``): per slab the premultiplied RGB and alpha of its samples alone
      (``SLAB_RGBA``) and the motion vector of its opacity-weighted mean point (``SLAB_MOTION``, 0 where the
      slab is empty); composited front to back they give ``color`` (over the background) and ``alpha``.

    The arrays are host (numpy) arrays, or GPU device arrays where the frame was rendered ``on_device``
    (:attr:`on_device`; :meth:`to_host` copies them back); the buffers are views indexed without an ellipsis,
    which numba's device arrays do not take.
    """

    data: np.ndarray
    camera: Camera
    jitter: tuple[float, float] = (0.0, 0.0)
    previous_camera: Camera | None = None
    pixels_per_voxel: float | None = None
    slabs: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.data.ndim != 3 or self.data.shape[2] != OUT_CHANNELS:
            raise ValueError(f"feature data must be (H, W, {OUT_CHANNELS}), got {self.data.shape}")
        if self.slabs is not None and (self.slabs.ndim != 4 or self.slabs.shape[1:] != self.data.shape[:2]
                                       + (SLAB_CHANNELS,)):
            raise ValueError(f"slabs must be (K, {self.height}, {self.width}, {SLAB_CHANNELS}), got "
                             f"{self.slabs.shape}")

    @property
    def on_device(self) -> bool:
        """Whether the buffers are GPU device arrays (``RayCaster.render(..., on_device=True)``)."""
        return hasattr(self.data, "copy_to_host")

    def to_host(self) -> "FeatureFrame":
        """This frame with its buffers in host memory (itself when they are there already)."""
        if not self.on_device:
            return self
        slabs = None if self.slabs is None else self.slabs.copy_to_host()
        return FeatureFrame(self.data.copy_to_host(), self.camera, self.jitter, self.previous_camera,
                            self.pixels_per_voxel, slabs)

    @property
    def height(self) -> int:
        return self.data.shape[0]

    @property
    def width(self) -> int:
        return self.data.shape[1]

    @property
    def color(self) -> np.ndarray:
        return channels(self.data, OUT_COLOR, OUT_COLOR + 3)

    @property
    def alpha(self) -> np.ndarray:
        return channels(self.data, OUT_ALPHA)

    @property
    def depth(self) -> np.ndarray:
        return channels(self.data, OUT_DEPTH)

    @property
    def max_rgba(self) -> np.ndarray:
        return channels(self.data, OUT_MAX_RGBA, OUT_MAX_RGBA + 4)

    @property
    def position(self) -> np.ndarray:
        return channels(self.data, OUT_POSITION, OUT_POSITION + 3)

    @property
    def motion(self) -> np.ndarray:
        return channels(self.data, OUT_MOTION, OUT_MOTION + 2)

    @property
    def motion_depth(self) -> np.ndarray:
        return channels(self.data, OUT_MOTION_DEPTH)

    def to_uint8(self) -> np.ndarray:
        """The colour as an (H, W, 3) uint8 image, ready for PNG."""
        return to_uint8(self.color)

    def save_npz(self, path: str | os.PathLike) -> None:
        """Write every buffer to a compressed .npz, atomically (temporary name, then rename)."""
        arrays = {name: getattr(self, name) for name in ("color", "alpha", "depth", "max_rgba", "position", "motion",
                                                         "motion_depth")}
        with atomic_write(path) as fh:
            np.savez_compressed(fh, jitter=np.asarray(self.jitter, dtype=np.float32), **arrays)
