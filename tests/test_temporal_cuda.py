"""The CUDA builds of TAAU, the layered TAAU, variant XS's base filter and the stretches agree with the CPU
kernels, alone, in the pipeline that keeps an XS frame on the device and in the benchmark's methods on a CUDA caster.

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
            colour[:, :3] = (0.2, 0.5, 0.7)  # one colour: boxes of one colour, whose pixels take it
            motion = (rng.random((h, w, 2), dtype=np.float32) - 0.5) * (1.2 if moves else 0.0)
            motion[:, w // 2:] *= -1.5 if moves else 1.0  # two layers moving apart: parallax, the depth test
            depth = rng.random((h, w), dtype=np.float32)
            jitter = (0.25 - 0.5 * (t % 2), -0.125 + 0.25 * (t % 3) / 2)
            args = (colour, motion, jitter, depth, rotation, ppv)
            close(f"TAAU {scale}x frame {t}", cpu(*args), gpu(*args).copy_to_host())
            close(f"TAAU {scale}x history {t}", cpu.history, gpu.history.copy_to_host())

        clamp_rotating = "always" if scale == 4 else "fine"  # the clamp under rotation: both settings that clamp
        cpu = LayeredUpsampler(scale, clamp_rotating=clamp_rotating)
        gpu = CudaLayeredUpsampler(scale, clamp_rotating=clamp_rotating)
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

    # 16x on a pan and a static view: far from the samples the narrow splat's Gaussian underflows (SPLAT_FLOOR)
    for name, cpu, gpu in (("TAAU", TemporalUpsampler(16, side_outputs=False), CudaTemporalUpsampler(16)),
                           ("layered", LayeredUpsampler(16), CudaLayeredUpsampler(16))):
        for t, (rotation, ppv, moves) in enumerate(views[3:]):
            if name == "TAAU":
                args = (rng.random((2, 2, 3), dtype=np.float32), np.zeros((2, 2, 2), np.float32), (0.25, -0.25),
                        rng.random((2, 2), dtype=np.float32), rotation, ppv)
            else:
                slabs = np.zeros((2, 2, 2, 6), np.float32)
                slabs[..., 3] = rng.random((2, 2, 2), dtype=np.float32)
                slabs[..., :3] = slabs[..., 3:4] * rng.random((2, 2, 2, 3), dtype=np.float32)
                args = (slabs, (0.25, -0.25), (0.1, 0.2, 0.3), rotation, ppv)
            out = cpu(*args)
            assert np.isfinite(out).all() and np.isfinite(cpu.history).all(), (name, t)
            close(f"{name} 16x frame {t}", out, gpu(*args).copy_to_host())

    # within one block of the filter's, and over blocks whose tiles' halos lie inside the image and past its edges
    for h_image, w_image in ((9, 11), (19, 37)):
        image = (rng.random((h_image, w_image, 3), dtype=np.float32) * 1.4 - 0.2)  # beyond [0, 1]: the clip counts
        for n in (1, 2):
            weights = rng.normal(0.0, 0.2, (n, 3, 5, 5)).astype(np.float32)
            weights[:, :, 2, 2] += 1.0
            bias = rng.normal(0.0, 0.01, (n, 3)).astype(np.float32)
            device = CudaBaseFilter(weights, bias)
            for clip in (False, True):
                close(f"filter of {n}, {h_image}x{w_image}, clip {clip}",
                      filter_image(image, weights, bias, clip_output=clip),
                      device.filter(image, clip_output=clip).copy_to_host(), tol=1e-5)

    # the motion flag stays on the device, never zeroed: each call's stamp tells this frame's answer from the last's
    from numba import cuda
    from volsr_core.temporal.cuda import MotionFlag

    still = np.zeros((4, 5, 2), np.float32)
    moving = still.copy()
    moving[3, 4, 1] = 0.01
    flag = MotionFlag()
    answers = [flag(cuda.to_device(m), 0) for m in (moving, still, still, moving, moving, still)]
    assert answers == [True, False, False, True, True, False], answers
    # an estimate written into a kept array must fit it
    taau = CudaTemporalUpsampler(2)
    kept = cuda.device_array((2 * h, 2 * w, 3), dtype=np.float32)
    colour, motion = rng.random((h, w, 3), dtype=np.float32), np.zeros((h, w, 2), np.float32)
    assert taau(colour, motion, (0.0, 0.0), out=kept) is kept
    try:
        taau(colour, motion, (0.0, 0.0), out=cuda.device_array((h, w, 3), dtype=np.float32))
    except ValueError as err:
        assert "shape" in str(err), err
    else:
        raise AssertionError("an out of the wrong shape was taken")
""")

PIPELINE = textwrap.dedent("""
    import numpy as np
    from numba import cuda
    from volsr_core.io import make_phantom
    from volsr_core.runtime.pipeline import Pipeline
    from volsr_core.scene import Camera, Volume, get_preset
    from volsr_core.scene.camera_paths import orbit

    # the device arrays the upscaler makes and the host arrays it uploads while it upscales a frame: each such call
    # costs a few tenths of a ms on a GPU (docs/performance-gpu.md), so they are made once and kept between frames
    made, counting = {"device_array": 0, "to_device": 0}, [False]
    for name in made:
        def counted(*args, _original=getattr(cuda, name), _name=name, **kwargs):
            made[_name] += counting[0]
            return _original(*args, **kwargs)
        setattr(cuda, name, counted)
    # and whether it asks the device if anything moves, an answer the host waits for: only where it counts (a view
    # of unknown rotation, or a still one with a history), not while the view rotates
    from volsr_core.temporal.cuda import MotionFlag
    asked, ask = [0], MotionFlag.__call__
    def counted_ask(self, *args):
        asked[0] += counting[0]
        return ask(self, *args)
    MotionFlag.__call__ = counted_ask
    # and when the host waits for the camera-cut check's sample: after the frame's filter is queued, not before
    import volsr_core.runtime.base_filter_cuda as bfc
    events, gather, queue_filter = [], bfc.every_nth, bfc.CudaBaseFilter.filter
    class Pending:
        def __init__(self, sample):
            self.sample = sample
        def copy_to_host(self):
            events.append("sample read")
            return self.sample.copy_to_host()
    bfc.every_nth = lambda *args: Pending(gather(*args))
    def logged_filter(self, *args, **kwargs):
        events.append("filter queued")
        return queue_filter(self, *args, **kwargs)
    bfc.CudaBaseFilter.filter = logged_filter

    def counted_upscale(upscale):
        def call(*args, **kwargs):
            made.update(device_array=0, to_device=0)
            asked[0] = 0
            counting[0] = True
            try:
                return upscale(*args, **kwargs)
            finally:
                counting[0] = False
        return call

    volume = Volume.from_record(make_phantom(shape=(32, 32, 32)))
    cameras = orbit(Camera.framing(volume.bounds), 3, degrees=3.0)
    for scale, size, stretch in ((2, (18, 14), 1), (4, (36, 28), 1), (4, (36, 28), 2), (16, (96, 64), 4)):
        cpu = Pipeline(volume, get_preset("CT-Phantom"), scale=scale, variant="XS", size=size, stretch=stretch)
        gpu = Pipeline(volume, get_preset("CT-Phantom"), scale=scale, variant="XS", size=size, stretch=stretch,
                       device="cuda")
        assert gpu.upscaler.on_device and not cpu.upscaler.on_device
        assert gpu.slabs == cpu.slabs == (scale // stretch // 2 - 1) * 2
        gpu.upscaler.upscale = counted_upscale(gpu.upscaler.upscale)
        for k, camera in enumerate(cameras):
            events.clear()
            a, b = cpu.render(camera), gpu.render(camera)
            assert events == (["filter queued", "sample read"] if k else ["filter queued"]), events
            assert isinstance(b, np.ndarray) and b.shape == a.shape == (size[1], size[0], 3)
            err = float(np.abs(a - b).max())
            print(f"XS {scale // stretch}x in {gpu.slabs} slabs, stretched {stretch}x, frame {k}: "
                  f"max abs difference {err:.2e}")
            assert err < 1e-4 and a.std() > 0.01, (err, a.std())
        # the third frame, once the histories swap: the filter's output is the one array made (and the stretch's, which
        # the upscaler makes too), and nothing uploaded
        assert made == {"device_array": 1 + (stretch > 1), "to_device": 0}, made
        assert asked[0] == 0, "a rotating view needs no motion flag"
        a, b = cpu.render(cameras[-1]), gpu.render(cameras[-1])  # the view held still: the flag says what moves
        assert asked[0] == 1 and float(np.abs(a - b).max()) < 1e-4
        # a pan by half the view's height: no camera jump, but motion no history follows; the device made the frame
        # with its history, read the sample, and makes it again without, as the CPU made it at once
        import dataclasses, math
        held = cameras[-1]
        shift = held.basis()[0] * held.distance * math.tan(math.radians(held.view_angle) / 2.0)
        pan = dataclasses.replace(held, position=held.position + shift, focal_point=held.focal_point + shift)
        events.clear()
        a, b = cpu.render(pan), gpu.render(pan)
        assert cpu.upscaler.last_reset_reason == gpu.upscaler.last_reset_reason != ""
        assert cpu.upscaler.resets == gpu.upscaler.resets
        assert events == ["filter queued", "sample read", "filter queued"], events
        assert float(np.abs(a - b).max()) < 1e-4
        assert gpu.last_timings["readback_ms"] > 0.0 == cpu.last_timings["readback_ms"]  # timed apart, on the GPU
        lr = gpu.last_low_resolution
        assert not lr.on_device and np.abs(lr.data - cpu.last_low_resolution.data).max() < 1e-4
""")

METHODS = textwrap.dedent("""
    import numpy as np
    from numba import cuda
    from volsr_core.io import make_phantom
    from volsr_core.render.raycaster import RayCaster
    from volsr_core.runtime.methods import Native, ReducedSize, Taau
    from volsr_core.scene import Camera, Volume, get_preset
    from volsr_core.scene.camera_paths import orbit
    from volsr_core.temporal.frames_cuda import resize_bicubic_device, resize_bilinear_device
    from volsr_core.temporal.resample import resize_bicubic, resize_bilinear

    rng = np.random.default_rng(3)
    for (h, w), (height, width) in (((5, 7), (16, 21)), ((6, 4), (6, 4)), ((3, 3), (11, 2))):  # up, same, mixed
        image = rng.random((h, w, 3), dtype=np.float32)
        err = float(np.abs(resize_bilinear(image, width, height)
                           - resize_bilinear_device(cuda.to_device(image), width, height).copy_to_host()).max())
        print(f"bilinear {w}x{h} -> {width}x{height}: max abs difference {err:.2e}")
        assert err < 1e-6, err
        cubic = resize_bicubic(image, width, height, a=-0.75, clamp=(0.0, 1.0))
        err = float(np.abs(cubic - resize_bicubic_device(cuda.to_device(image), width, height, a=-0.75,
                                                         clamp=(0.0, 1.0)).copy_to_host()).max())
        print(f"bicubic {w}x{h} -> {width}x{height}: max abs difference {err:.2e}")
        assert err < 1e-6 and cubic.min() >= 0.0 and cubic.max() <= 1.0, err

    volume = Volume.from_record(make_phantom(shape=(32, 32, 32)))
    cameras = orbit(Camera.framing(volume.bounds), 3, degrees=3.0)
    casters = [RayCaster(volume, get_preset("CT-Phantom"), device=device, start_jitter="ign") for device in ("cpu",
                                                                                                       "cuda")]
    size = (32, 24)
    for make in (lambda c: Native(c, size, 1), lambda c: Native(c, size, 2), lambda c: ReducedSize(c, size, 3),
                 lambda c: Taau(c, size, 2), lambda c: Taau(c, size, 4, slabs=2)):
        cpu, gpu = make(casters[0]), make(casters[1])
        for k, camera in enumerate(cameras):
            a, b = cpu(camera), gpu(camera)
            assert isinstance(b.image, np.ndarray) and b.image.shape == a.image.shape == (size[1], size[0], 3)
            assert a.ms_readback == 0.0 and b.ms_readback > 0.0 and b.ms_total > 0.0
            err = float(np.abs(a.image - b.image).max())
            print(f"{gpu.label}, frame {k}: max abs difference {err:.2e}")
            assert err < 1e-4 and a.image.std() > 0.01, (err, a.image.std())
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
    # TAAU and layered at 2x and 4x (frame and history, 5 views), both at 16x (2 views), the filters
    assert run_script(SCRIPT).count("max abs difference") == 2 * 2 * 2 * 5 + 2 * 2 + 2 * 2 * 2


def test_the_xs_pipeline_on_the_device_gives_the_cpu_pipelines_images():
    """VolSR XS with ``device="cuda"``: frame, TAAU (2x) or layered TAAU (4x) and filter on the device (and the
    stretch of XS 2x + bicubic 2x, and of XS 4x + bicubic 4x at 16x), one image back; the images of the CPU pipeline,
    frame by frame, and the LR frame there when asked for; once its histories swap, the upscaler makes one device
    array a frame (the filter's output) and uploads nothing."""
    assert run_script(PIPELINE).count("max abs difference") == 4 * 3


def test_every_method_on_a_cuda_caster_makes_the_cpu_images_on_the_device():
    """Native (1 and 2 spp), 1/3 size + bilinear, TAAU and the layered TAAU on a CUDA ray caster: the full-size image
    made on the device (the bilinear stretch too, and VolSR's bicubic one alone) gives the CPU methods' images, and
    its copy to the host is timed apart (``ms_readback``, 0 on the CPU)."""
    assert run_script(METHODS).count("max abs difference") == 3 * 2 + 5 * 3


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


def test_a_frames_channels_on_the_device_are_numbas_own_views_made_without_walking_the_pixels(monkeypatch):
    """A feature channel of a frame on the GPU is a strided view, and numba-cuda slices one by walking each pixel's
    contiguous run in Python: 190 ms for a 256² frame's colour on the lent H200, where the whole TAAU takes less.
    ``channels`` gives numba's own view (shape, strides, device pointer, extent) without that walk. A real
    ``DeviceNDArray`` over a made-up device pointer (no GPU: nothing is read or written through it)."""
    import ctypes

    import numpy as np
    from numba.cuda.cudadrv import dummyarray
    from numba.cuda.cudadrv.devicearray import DeviceNDArray
    from numba.cuda.cudadrv.driver import MemoryPointer

    from volsr_core.render.device import channels
    from volsr_core.render.features import FeatureFrame
    from volsr_core.render.layout import OUT_CHANNELS, OUT_COLOR, OUT_MOTION, OUT_MOTION_DEPTH
    from volsr_core.scene import Camera

    h, w = 24, 40
    data = DeviceNDArray((h, w, OUT_CHANNELS), (w * OUT_CHANNELS * 4, OUT_CHANNELS * 4, 4), np.float32,
                         gpu_data=MemoryPointer(None, ctypes.c_void_p(1 << 20), h * w * OUT_CHANNELS * 4))
    cases = [(OUT_COLOR, OUT_COLOR + 3), (OUT_MOTION, OUT_MOTION + 2), (OUT_MOTION_DEPTH, None)]
    # numba's own slicing (__getitem__ without its context check, which needs a GPU)
    expected = [data._do_getitem((slice(None), slice(None), a if b is None else slice(a, b))) for a, b in cases]
    monkeypatch.setattr(dummyarray.Array, "iter_contiguous_extent",
                        lambda self: pytest.fail("walked the view's contiguous runs"))
    frame = FeatureFrame(data, Camera.framing((0, 1, 0, 1, 0, 1)))
    for (a, b), want, got in zip(cases, expected, (frame.color, frame.motion, frame.motion_depth)):
        assert type(got) is DeviceNDArray
        assert (got.shape, got.strides, got.dtype) == (want.shape, want.strides, want.dtype)
        assert got.device_ctypes_pointer.value == want.device_ctypes_pointer.value == (1 << 20) + 4 * a
        assert got.gpu_data.size == want.gpu_data.size
        host = np.zeros((h, w, OUT_CHANNELS), np.float32)
        assert channels(host, a, b).base is host and channels(host, a, b).shape == want.shape


def test_the_device_kernels_compile_for_a_gpu():
    """The simulator runs the kernels as Python; numba-cuda's own typing and lowering, what a GPU compiles, are
    checked by compiling each of them to PTX for an H100/H200 (sm_90), no GPU needed, with the argument types the
    pipeline passes (the renderer's buffers are strided views). NVRTC and NVVM come with ``make test`` (the dev extra's
    ``nvidia-cuda-nvrtc-cu12`` and ``nvidia-cuda-nvcc-cu12``)."""
    import numba
    import numpy as np
    from numba import cuda

    try:
        cuda.compile_ptx(lambda a: None, "void(float32[:])", cc=(9, 0))
    except Exception as err:  # numba-cuda raises its own error types when NVRTC or NVVM cannot be found
        if os.environ.get("CI") == "true":
            raise
        pytest.skip(f"numba-cuda cannot compile PTX here ({type(err).__name__}): install the dev extra")
    from volsr_core.render.layout import OUT_CHANNELS, SLAB_CHANNELS
    from volsr_core.runtime import base_filter_cuda as bf
    from volsr_core.temporal import cuda as tc
    from volsr_core.temporal import frames_cuda as fc

    frame = np.zeros((8, 8, OUT_CHANNELS), np.float32)
    colour, motion, depth = frame[:, :, 0:3], frame[:, :, 12:14], frame[:, :, 14]  # views, as FeatureFrame's
    hr3, slabs = np.zeros((16, 16, 3), np.float32), np.zeros((2, 8, 8, SLAB_CHANNELS), np.float32)
    flag = np.zeros(1, np.int32)
    taps = np.zeros(5, np.float32)
    history, box = np.zeros((16, 16, 5), np.float32), np.zeros((8, 8, 8), np.float32)
    info = np.zeros((2, 8, 8, 11), np.float32)
    layered = np.zeros((2, 16, 16, 5), np.float32)
    f32 = np.float32(1.0)
    calls = [(tc._flag_motion, (motion, 0, 1e-3, 7, flag)),  # the stamp an int, as MotionFlag passes it
             (tc._flag_motion, (slabs.reshape(16, 8, SLAB_CHANNELS), 4, 1e-3, 7, flag)),
             (tc._taau_prepass, (colour, motion, 2, 0.5, box)),
             (tc._taau_pixels, (history, True, colour, motion, depth, box, 2, 0.1, 0.2, 8.0, 0.5, 1.0, 0.1, True, hr3,
                                history)),
             (tc._layered_prepass, (slabs, True, info)),
             (tc._layered_pixels, (layered, True, slabs, info, 2, 0.1, 0.2, 8.0, 0.5, 1.0, True, taps[:3], hr3,
                                   layered)),
             (bf.filter_kernel(np.ones((2, 3, 5, 5)), np.ones((2, 3))), (hr3, f32, f32, hr3)),
             (bf.filter_kernel(np.ones((1, 3, 5, 5)), np.ones((1, 3))), (hr3, f32, f32, hr3)),
             (bf._gather_every_nth, (motion, 2, np.zeros((4, 4, 2), np.float32))),
             (fc._resample_pixels, (hr3, np.zeros((16, 4), np.int64), np.zeros((16, 4), np.float32),
                                    np.zeros((16, 4), np.int64), np.zeros((16, 4), np.float32), f32, f32, hr3)),
             (fc._add_sample, (np.zeros((16, 16, 3), np.float64), hr3, True)),
             (fc._divide, (np.zeros((16, 16, 3), np.float64), 2.0, hr3))]
    for kernel, args in calls:
        ptx, _ = cuda.compile_ptx(kernel.py_func, numba.types.void(*(numba.typeof(a) for a in args)), cc=(9, 0))
        assert ".entry" in ptx, kernel
