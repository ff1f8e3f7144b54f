"""Supersampled ground truth: the average of N jittered renders of a static camera."""
from __future__ import annotations

import numpy as np

from volsr_core.render.raycaster import RayCaster
from volsr_core.scene.camera import Camera
from volsr_core.temporal.jitter import halton_jitter


def render_supersampled(raycaster: RayCaster, camera: Camera, width: int, height: int | None = None,
                        spp: int = 16, seed: int = 0, on_device: bool = False) -> np.ndarray:
    """(H, W, 3) float32 colour averaged over ``spp`` Halton(2, 3) jitter offsets (a box filter).

    ``spp=1`` renders the pixel centres without jitter; each render is the colour-only ray program
    (:meth:`RayCaster.render_color`). Sample i is rendered with ray-start seed
    ``seed + i`` (used when the caster's start jitter is on: each sample then starts its rays at other
    offsets, so the average also removes the rings a fixed ray start leaves). ``on_device`` (a "cuda" caster)
    renders, sums and averages on the GPU and returns a device array (its kernels may still be running).
    """
    if spp < 1:
        raise ValueError("spp must be at least 1")
    if spp == 1:
        return raycaster.render_color(camera, width, height, seed=seed, on_device=on_device)
    if on_device:
        from volsr_core.temporal.frames_cuda import DeviceAverage

        buffer = average = None
        for i in range(spp):
            buffer = raycaster.render_color(camera, width, height, jitter=halton_jitter(i, spp), seed=seed + i,
                                            out=buffer, on_device=True)
            average = average or DeviceAverage(buffer.shape)
            average.add(buffer)
        return average.mean()
    acc = None
    buffer = None
    for i in range(spp):
        buffer = raycaster.render_color(camera, width, height, jitter=halton_jitter(i, spp), seed=seed + i, out=buffer)
        acc = buffer.astype(np.float64) if acc is None else acc + buffer
    return (acc / spp).astype(np.float32)
