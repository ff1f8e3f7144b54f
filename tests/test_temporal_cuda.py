"""The CUDA builds of TAAU, the layered TAAU and variant XS's base filter agree with the CPU kernels, alone and in the
pipeline that keeps an XS frame on the device.

Frames with motion, parallax, empty slabs, a still and a static view go through the CPU classes and their CUDA
twins side by side; outputs and histories must agree to float rounding. Without a GPU this runs in Numba's CUDA
simulator (NUMBA_ENABLE_CUDASIM=1, set before numba is imported, hence the subprocess) on tiny frames; with a GPU
set VOLSR_TEST_REAL_CUDA=1 to use it.
"""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("numba.cuda", reason="numba-cuda is not installed")

SCRIPT = textwrap.dedent("""
    import numpy as np
    from volsr_core.runtime.base_filter import filter_image
    from volsr_core.runtime.base_filter_cuda import CudaBaseFilter
    from volsr_core.temporal.cuda import CudaLayeredUpsampler, CudaTemporalUpsampler
    from volsr_core.temporal.layered import LayeredUpsampler
    from volsr_core.temporal.taau import TemporalUpsampler

    rng = np.random.default_rng(7)
    h, w = 6, 8
    # (rotation in degrees, pixels per voxel, whether anything moves): rotating with the bilinear blend on, rotating
    # without it, a pan (still: clamped, narrow splat), nothing moving (static)
    views = [(2.0, 1.0, True), (2.0, 1.0, True), (5.0, None, True), (0.0, 1.0, True), (0.0, None, False)]

    def close(name, cpu, gpu, tol=2e-5):
        err = float(np.abs(np.asarray(cpu) - np.asarray(gpu)).max())
        print(name, "max abs difference", err)
        assert err < tol, (name, err)

    for scale in (2, 4):
        cpu, gpu = TemporalUpsampler(scale, side_outputs=False), CudaTemporalUpsampler(scale)
        for t, (rotation, ppv, moves) in enumerate(views):
            colour = rng.random((h, w, 3), dtype=np.float32)
            motion = (rng.random((h, w, 2), dtype=np.float32) - 0.5) * (1.2 if moves else 0.0)
            motion[:, w // 2:] *= -1.5 if moves else 1.0  # two layers moving apart: parallax, the depth test
            depth = rng.random((h, w), dtype=np.float32)
            jitter = (0.25 - 0.5 * (t % 2), -0.125 + 0.25 * (t % 3) / 2)
            args = (colour, motion, jitter, depth, rotation, ppv)
            close(f"TAAU {scale}x frame {t}", cpu(*args), gpu(*args).copy_to_host())
            close(f"TAAU {scale}x history {t}", cpu.history, gpu.history.copy_to_host())

        cpu, gpu = LayeredUpsampler(scale), CudaLayeredUpsampler(scale)
        for t, (rotation, ppv, moves) in enumerate(views):
            slabs = np.zeros((2, h, w, 6), np.float32)
            alpha = rng.random((2, h, w), dtype=np.float32)
            alpha[rng.random((2, h, w)) < 0.3] = 0.0  # empty slab pixels, and whole empty neighbourhoods
            alpha[0, :, :3] = 0.0
            slabs[..., 3] = alpha
            slabs[..., :3] = alpha[..., None] * rng.random((2, h, w, 3), dtype=np.float32)
            slabs[..., 4:] = np.where(alpha[..., None] > 0, (rng.random((2, h, w, 2)) - 0.5) * 1.5, 0.0) \\
                if moves else 0.0
            jitter = (0.125 - 0.25 * (t % 2), 0.375 - 0.5 * (t % 3) / 2)
            args = (slabs, jitter, (0.1, 0.2, 0.3), rotation, ppv)
            close(f"layered {scale}x frame {t}", cpu(*args), gpu(*args).copy_to_host())
            close(f"layered {scale}x history {t}", cpu.history, gpu.history.copy_to_host())

    image = (rng.random((9, 11, 3), dtype=np.float32) * 1.4 - 0.2)  # beyond [0, 1]: the input clip counts
    for n in (1, 2):
        weights = rng.normal(0.0, 0.2, (n, 3, 5, 5)).astype(np.float32)
        weights[:, :, 2, 2] += 1.0
        bias = rng.normal(0.0, 0.01, (n, 3)).astype(np.float32)
        device = CudaBaseFilter(weights, bias)
        for clip in (False, True):
            close(f"filter of {n}, clip {clip}", filter_image(image, weights, bias, clip_output=clip),
                  device.filter(image, clip_output=clip).copy_to_host(), tol=1e-5)
""")

PIPELINE = textwrap.dedent("""
    import numpy as np
    from volsr_core.io import make_phantom
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.scene import Camera, Volume, get_preset
    from volsr_core.scene.camera_paths import orbit

    volume = Volume.from_record(make_phantom(shape=(32, 32, 32)))
    cameras = orbit(Camera.framing(volume.bounds), 3, degrees=3.0)
    for scale, size in ((2, (18, 14)), (4, (36, 28))):
        cpu = Pipeline(volume, get_preset("CT-Phantom"), scale=scale, variant="XS", size=size)
        gpu = Pipeline(volume, get_preset("CT-Phantom"), scale=scale, variant="XS", size=size, device="cuda")
        assert gpu.upscaler.on_device and not cpu.upscaler.on_device and gpu.slabs == cpu.slabs == (scale // 2 - 1) * 2
        for k, camera in enumerate(cameras):
            a, b = cpu.render(camera), gpu.render(camera)
            assert isinstance(b, np.ndarray) and b.shape == a.shape == (size[1], size[0], 3)
            err = float(np.abs(a - b).max())
            print(f"XS {scale}x in {gpu.slabs} slabs, frame {k}: max abs difference {err:.2e}")
            assert err < 1e-4 and a.std() > 0.01, (err, a.std())
        lr = gpu.last_low_resolution
        assert not lr.on_device and np.abs(lr.data - cpu.last_low_resolution.data).max() < 1e-4
""")


def run_script(script: str) -> str:
    """``script``'s stdout, run in a fresh interpreter in the simulator (or on the GPU with VOLSR_TEST_REAL_CUDA=1);
    a failure shows its output."""
    env = dict(os.environ)
    if os.environ.get("VOLSR_TEST_REAL_CUDA") != "1":
        env["NUMBA_ENABLE_CUDASIM"] = "1"
    result = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    return result.stdout


def test_cuda_temporal_kernels_match_the_cpu_kernels():
    assert run_script(SCRIPT).count("max abs difference") == 2 * 2 * 2 * 5 + 4


def test_the_xs_pipeline_on_the_device_gives_the_cpu_pipelines_images():
    """VolSR XS with ``device="cuda"``: frame, TAAU (2x) or layered TAAU (4x) and filter on the device, one image back;
    the images of the CPU pipeline, frame by frame, and the LR frame there when asked for."""
    assert run_script(PIPELINE).count("max abs difference") == 2 * 3


def test_a_frames_buffers_index_as_numba_device_arrays_index():
    """The simulator's device arrays are numpy arrays and take any index; numba's own (``DeviceNDArray``, which
    slices through ``dummyarray.Array``) take no ellipsis. A frame left on the device is read through its buffer
    properties, so each must index as those do."""
    from numba.cuda.cudadrv.dummyarray import Array

    from volsr_core.render.features import FeatureFrame
    from volsr_core.render.layout import OUT_CHANNELS, SLAB_CHANNELS
    from volsr_core.scene import Camera

    h, w = 6, 8
    data = Array.from_desc(0, (h, w, OUT_CHANNELS), (w * OUT_CHANNELS * 4, OUT_CHANNELS * 4, 4), 4)
    slabs = Array.from_desc(0, (2, h, w, SLAB_CHANNELS), (h * w * SLAB_CHANNELS * 4, w * SLAB_CHANNELS * 4,
                                                          SLAB_CHANNELS * 4, 4), 4)
    frame = FeatureFrame(data, Camera.framing((0, 1, 0, 1, 0, 1)), slabs=slabs)
    shapes = {name: getattr(frame, name).shape for name in ("color", "alpha", "depth", "max_rgba", "position",
                                                             "motion", "motion_depth")}
    assert shapes == {"color": (h, w, 3), "alpha": (h, w), "depth": (h, w), "max_rgba": (h, w, 4),
                      "position": (h, w, 3), "motion": (h, w, 2), "motion_depth": (h, w)}
    assert frame.slabs.reshape(2 * h, w, SLAB_CHANNELS)[0].shape == (2 * h, w, SLAB_CHANNELS)
