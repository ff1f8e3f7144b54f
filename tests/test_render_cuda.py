"""The CUDA build of the ray program agrees with the CPU build, depth slabs and the colour-only program included.

Without a GPU this runs in Numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1, set before numba is
imported, hence the subprocess) on a tiny image; with a GPU set VOLSR_TEST_REAL_CUDA=1 to use it.
"""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytest.importorskip("numba.cuda", reason="numba-cuda is not installed")

SCRIPT = textwrap.dedent("""
    import sys
    import numpy as np
    sys.path.insert(0, {tests!r})
    from test_render_reference import oblique_volume, shaded_tf
    from volsr_core.render import RayCaster
    from volsr_core.scene import Camera

    volume = oblique_volume()
    camera = Camera.framing(volume.bounds, direction=(0.3, 1.0, -0.4), view_up=(0, 0, 1)).zoom(2.0)
    kwargs = dict(jitter=(0.2, -0.1), previous_camera=camera.azimuth(3))
    for mode, jitter in (("max_alpha", False), ("threshold", True), ("mean", "ign")):
        opts = dict(block_size=4, motion_depth=mode, start_jitter=jitter)
        cpu = RayCaster(volume, shaded_tf(), **opts).render(camera, 8, 6, seed=3, slabs=3, **kwargs)
        gpu = RayCaster(volume, shaded_tf(), device="cuda", **opts).render(camera, 8, 6, seed=3, slabs=3, **kwargs)
        assert cpu.alpha.max() > 0.5, "scene must be visible"
        err = max(np.abs(cpu.data - gpu.data).max(), np.abs(cpu.slabs - gpu.slabs).max())
        print(mode, jitter, "max abs difference", err)
        assert err < 1e-4, err
        view = dict(seed=3, jitter=(0.2, -0.1))
        colour = RayCaster(volume, shaded_tf(), device="cuda", **opts).render_color(camera, 8, 6, **view)
        cpu_colour = RayCaster(volume, shaded_tf(), **opts).render(camera, 8, 6, **view).color
        print(mode, jitter, "colour only: max abs difference", np.abs(colour - cpu_colour).max())
        assert colour.shape == (6, 8, 3) and np.abs(colour - cpu_colour).max() < 1e-4
""")


def test_cuda_path_matches_cpu_path():
    env = dict(os.environ)
    if os.environ.get("VOLSR_TEST_REAL_CUDA") != "1":
        env["NUMBA_ENABLE_CUDASIM"] = "1"
    tests = str(Path(__file__).resolve().parent)
    result = subprocess.run([sys.executable, "-c", SCRIPT.format(tests=tests)], env=env,
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
