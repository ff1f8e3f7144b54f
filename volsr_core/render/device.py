"""Frames made on the GPU, seen from the host: when one is ready, its copy back, and an array put beside it.

Kernels launched by numba-cuda run asynchronously; a time taken right after a launch misses them. Every timed
step that ends with a device array ends with :func:`ready_at`, and the copy to host memory, which a viewer showing
the frame from the GPU never makes, is :func:`to_host` with its own time. Host arrays pass through both.
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np


def is_device_array(array: Any) -> bool:
    """Whether ``array`` lives on the GPU (numba's device arrays, and the CUDA simulator's)."""
    return hasattr(array, "copy_to_host")


def channels(buffer: Any, start: int, stop: int | None = None) -> Any:
    """``buffer[:, :, start:stop]`` of an (H, W, C) host or device array as a view; ``stop`` None: the one channel
    ``buffer[:, :, start]``, (H, W).

    numba-cuda slices a strided device array by walking each of its contiguous runs in Python
    (``DeviceNDArray._do_getitem`` through ``dummyarray.Array.iter_contiguous_extent``): one run per pixel for a
    feature channel, about 190 ms for a 256² frame's colour on the lent H200 (docs/performance-gpu.md), more than the
    whole TAAU there. A numba device array's view is made here from its shape and strides alone: the same shape,
    strides, device pointer and extent as numba's own slice, in constant time."""
    item = (slice(None), slice(None), start if stop is None else slice(start, stop))
    if not is_device_array(buffer) or not hasattr(buffer, "gpu_data") or min(buffer.strides) < 0:
        return buffer[item]  # host arrays, and the simulator's, slice as numpy does
    (height, width, _), (row, column, channel) = buffer.shape, buffer.strides
    count = 1 if stop is None else stop - start
    begin = start * channel
    end = begin + (height - 1) * row + (width - 1) * column + (count - 1) * channel + buffer.dtype.itemsize
    shape, strides = ((height, width), (row, column)) if stop is None else \
        ((height, width, count), (row, column, channel))
    return type(buffer)(shape=shape, strides=strides, dtype=buffer.dtype, stream=buffer.stream,
                        gpu_data=buffer.gpu_data.view(begin, end))


def placed_like(host: np.ndarray, array: Any) -> Any:
    """``host`` where ``array`` lives: copied to the GPU for a device array, as it is for a host one."""
    if not is_device_array(array):
        return host
    from numba import cuda

    return cuda.to_device(host)


def ready_at(array: Any) -> float:
    """``time.perf_counter()`` once ``array`` is made: for a device array, after the GPU has finished its work."""
    if is_device_array(array):
        from numba import cuda

        cuda.synchronize()
    return time.perf_counter()


def to_host(array: Any) -> tuple[np.ndarray, float]:
    """``array`` in host memory and the ms its copy from the GPU took (0.0 for a host array, returned as it is)."""
    if not is_device_array(array):
        return array, 0.0
    started = time.perf_counter()
    host = array.copy_to_host()
    return host, 1000.0 * (time.perf_counter() - started)
