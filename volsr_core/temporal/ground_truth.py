"""High-resolution ground truth for a camera path: supersampled (default) or the paper's TAA.

- ``supersampled``: each frame on its own, the camera held still, the average of ``spp``
  Halton(2, 3)-jittered renders (default 16). Every frame is converged and owes nothing to its
  neighbours: no ghosting, no lag, no disocclusion noise. This is the default because the
  network should learn the image the renderer converges to, not a temporal filter's artefacts.
- ``taa``: the seed paper's choice: one jittered render per frame, accumulated by temporal
  anti-aliasing over the moving sequence (``warmup`` extra frames at the start camera first, so
  frame 0 is converged too). About ``spp`` times cheaper, but it carries TAA's blur and ghosting.
"""
from __future__ import annotations

from typing import Iterator, Sequence

import numpy as np

from volsr_core.render.raycaster import RayCaster
from volsr_core.scene.camera import Camera
from volsr_core.temporal.jitter import halton_jitter
from volsr_core.temporal.supersample import render_supersampled
from volsr_core.temporal.taa import TemporalAntiAliasing

MODES = ("supersampled", "taa")


def supersampled_truth(caster: RayCaster, camera: Camera, index: int, width: int, height: int,
                       spp: int = 16, on_device: bool = False) -> np.ndarray:
    """The (H, W, 3) float32 "supersampled" ground truth of frame ``index`` of a camera path (what
    :func:`ground_truth_frames` yields for it, and ``volsr bench`` scores against): ``spp`` jittered samples, their
    ray-start seeds apart from the LR frames' (which count frames from 0); ``on_device`` as
    :func:`~volsr_core.temporal.supersample.render_supersampled` takes it."""
    return render_supersampled(caster, camera, width, height, spp=spp, seed=10**6 + index * spp, on_device=on_device)


def ground_truth_frames(caster: RayCaster, cameras: Sequence[Camera], width: int, height: int, *,
                        mode: str = "supersampled", spp: int = 16, warmup: int = 16,
                        history_weight: float = 0.9) -> Iterator[np.ndarray]:
    """Yield one (H, W, 3) float32 ground-truth colour image per camera, in order."""
    if mode == "supersampled":
        for t, camera in enumerate(cameras):
            yield supersampled_truth(caster, camera, t, width, height, spp)
        return
    if mode != "taa":
        raise ValueError(f"ground-truth mode must be one of {MODES}, got {mode!r}")
    taa = TemporalAntiAliasing(history_weight=history_weight)
    previous = None
    frame_index = 0
    path = [cameras[0]] * warmup + list(cameras)
    for i, camera in enumerate(path):
        frame = caster.render(camera, width, height, jitter=halton_jitter(frame_index, 16),
                              previous_camera=previous, seed=frame_index)
        output = taa(frame.color, frame.motion)
        previous = camera
        frame_index += 1
        if i >= warmup:
            yield output
