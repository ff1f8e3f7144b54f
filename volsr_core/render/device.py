"""Frames made on the GPU, seen from the host: when one is ready, and its copy back.

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
