"""Numba kernels cached on disk compile anew when a module whose code they compile in changes.

Numba keys a kernel's disk cache (``cache=True``) on the kernel's own source file alone, so a kernel that inlines the
ray program's or TAAU's stages from another module kept its old machine code after those stages changed (numba
issue 1833). Such kernels close over :func:`~volsr_core.hashing.sources_sha256` of those modules, which numba hashes
into the cache key; the helpers they call are not cached apart.
"""
from __future__ import annotations

import ast
import importlib
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from types import ModuleType

from numba.core.dispatcher import Dispatcher

from volsr_core.hashing import sources_sha256

PACKAGE = Path(__file__).resolve().parents[1] / "volsr_core"


def _kernel_modules() -> list[ModuleType]:
    """The package's modules that compile numba functions with a disk cache (those needing a GPU toolkit aside)."""
    names = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if "cache=True" in path.read_text() and "cuda" not in path.stem:
            names.append("volsr_core." + ".".join(path.relative_to(PACKAGE).with_suffix("").parts))
    return [importlib.import_module(name) for name in names]


def _imported_from(module_name: str) -> dict[str, str]:
    """Names a module imports from other volsr_core modules (``from volsr_core.x import name``), to their module."""
    tree = ast.parse(Path(sys.modules[module_name].__file__).read_text())
    return {alias.asname or alias.name: node.module for node in ast.walk(tree)
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("volsr_core.")
            for alias in node.names}


def compiled_in(dispatcher: Dispatcher) -> set[str]:
    """The volsr_core modules, other than the dispatcher's own, whose functions or constants its compiled code holds:
    the jitted functions it calls (through globals and closures, transitively) and the names those read from other
    volsr_core modules."""
    home, found, seen = dispatcher.py_func.__module__, set(), set()

    def walk(function) -> None:
        if id(function) in seen:
            return
        seen.add(id(function))
        py_func = function.py_func
        imported, names = _imported_from(py_func.__module__), py_func.__code__.co_names
        used = [py_func.__globals__[n] for n in names if n in py_func.__globals__]
        used += [cell.cell_contents for cell in py_func.__closure__ or ()]
        for name in names:
            value = py_func.__globals__.get(name)
            if imported.get(name, home) != home and not isinstance(value, (Dispatcher, ModuleType)):
                found.add(imported[name])  # a constant from another module, compiled in as a literal
        for value in used:
            if isinstance(value, ModuleType) and value.__name__.startswith("volsr_core.") and value.__name__ != home:
                found.add(value.__name__)
            if isinstance(value, Dispatcher):
                if value.py_func.__module__ != home:
                    found.add(value.py_func.__module__)
                walk(value)

    walk(dispatcher)
    return found


def _cached_kernels() -> list[tuple[str, Dispatcher]]:
    """(name, dispatcher) of every module-level numba function with a disk cache that is not always inlined (an
    inlined one is compiled into its callers' code, from their source, and its own cache is never read for them)."""
    kernels = []
    for module in _kernel_modules():
        for name, value in vars(module).items():
            if (isinstance(value, Dispatcher) and value.py_func.__module__ == module.__name__
                    and type(value._cache).__name__ != "NullCache" and value.targetoptions.get("inline") != "always"):
                kernels.append((f"{module.__name__}.{name}", value))
    return kernels


def test_every_cached_kernel_is_keyed_on_the_modules_it_compiles_in():
    kernels = dict(_cached_kernels())
    for needed in ("volsr_core.render.cpu._render_rows", "volsr_core.temporal.taau._kernel",
                   "volsr_core.temporal.layered._kernel", "volsr_core.temporal.taa._taa_kernel"):
        assert needed in kernels, f"{needed} should be a cached kernel"
    offences = []
    for name, kernel in kernels.items():
        modules = compiled_in(kernel)
        if not modules:
            continue
        digest = sources_sha256(*(sys.modules[m] for m in modules))
        cells = [cell.cell_contents for cell in kernel.py_func.__closure__ or ()]
        if digest not in cells:
            offences.append(f"{name} compiles in {', '.join(sorted(modules))} but does not close over their "
                            "sources_sha256")
    assert not offences, "\n".join(offences)
    # the walk finds what a kernel compiles in: the ray program's stages and their layout constants
    assert compiled_in(kernels["volsr_core.render.cpu._render_rows"]) == {"volsr_core.render.stages",
                                                                        "volsr_core.render.layout"}
    assert compiled_in(kernels["volsr_core.temporal.taa._taa_kernel"]) == {"volsr_core.temporal.color",
                                                                         "volsr_core.temporal.stages"}


def test_sources_sha256_is_of_the_set_of_sources():
    import volsr_core.render.layout as layout
    import volsr_core.render.stages as stages

    assert sources_sha256(stages, layout) == sources_sha256(layout, stages, layout)
    assert sources_sha256(stages, layout) != sources_sha256(stages)


STAGE = """
import numba


@numba.njit(inline="always", cache=True)
def step(x):
    return x + {increment}
"""

KERNEL = """
import numba
import numpy as np

from volsr_core.hashing import sources_sha256
import stage


def build(sources):
    @numba.njit(parallel=True, cache=True)
    def kernel(x, out):
        sources
        for i in numba.prange(x.shape[0]):
            out[i] = stage.step(x[i])
    return kernel


kernel = build(sources_sha256(stage))
out = np.empty(4)
kernel(np.zeros(4), out)
print(out[0], len(kernel.stats.cache_hits), len(kernel.stats.cache_misses))
"""


def test_a_kernel_keyed_on_its_stage_module_compiles_anew_when_that_changes(tmp_path):
    """The pattern the package's kernels follow, end to end with numba's disk cache (in-tree ``__pycache__``): a
    second run loads the kernel from the cache; after the stage module changes it compiles the new stage."""
    (tmp_path / "kernel.py").write_text(KERNEL)

    def run(increment: float) -> tuple[float, int, int]:
        (tmp_path / "stage.py").write_text(textwrap.dedent(STAGE.format(increment=increment)))
        env = {"PYTHONPATH": f"{tmp_path}:{PACKAGE.parent}", "PATH": "/usr/bin:/bin", "NUMBA_NUM_THREADS": "2",
               "PYTHONDONTWRITEBYTECODE": "1"}  # no .pyc: one written in the same second would hide the new stage
        result = subprocess.run([sys.executable, "kernel.py"], cwd=tmp_path, capture_output=True, text=True,
                                env=env, timeout=300)
        assert result.returncode == 0, result.stderr
        value, hits, misses = result.stdout.split()
        return float(value), int(hits), int(misses)

    assert run(1.0) == (1.0, 0, 1)  # compiled and saved
    assert run(1.0) == (1.0, 1, 0)  # loaded
    assert run(2.0) == (2.0, 0, 1)  # the stage changed: compiled anew, not the old code loaded


ONE_SIGNATURE = """
from volsr_core.io import make_phantom
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.scene import Camera, Volume, get_preset
from volsr_core.temporal import taau

volume = Volume.from_record(make_phantom(shape=(32, 32, 32)))
pipeline = Pipeline(volume, get_preset("CT-Phantom"), scale=2, size=(32, 32), variant="XS", threads=2)
camera = Camera.framing(volume.bounds)
for degrees in (0, 2, 4):  # the first frame has no motion (a cut), the others do
    pipeline.render(camera.azimuth(degrees))
print(len(taau._prepass.signatures), len(taau._kernel.signatures), len(taau._moves.signatures))
"""


def test_a_pipelines_first_frame_and_the_next_run_taau_with_one_compiled_signature():
    """The frame after a cut has no motion to follow; its zero vectors are strided as every frame's own, so that
    TAAU's kernels compile once for both (a contiguous array compiled them a second time, 7 s at first use)."""
    result = subprocess.run([sys.executable, "-c", ONE_SIGNATURE], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    prepass, kernel, moves = (int(n) for n in result.stdout.split())
    assert (prepass, kernel) == (1, 1) and moves <= 1  # the motion test runs only where its answer counts


FIRST_FRAMES = """
import json

import numba.core.event as event

from volsr_core.io import make_phantom
from volsr_core.render import RayCaster
from volsr_core.runtime.pipeline import Pipeline
from volsr_core.scene import Camera, Volume, get_preset

volume = Volume.from_record(make_phantom(shape=(40, 36, 32)))
look = get_preset("CT-Bone")  # another look and other sizes than the warm-up's
camera = Camera.framing(volume.bounds)
with event.install_recorder("numba:compile") as recorder:
    for settings in (dict(scale=2, size=(48, 40)), dict(scale=4, size=(96, 80)),
                     dict(scale=4, stretch=2, size=(96, 80))):
        pipeline = Pipeline(volume, look, variant="XS", threads=2, **settings)
        for degrees in (0, 3, 6):
            pipeline.render(camera.azimuth(degrees))
    RayCaster(volume, look).render_color(camera, 40, 30)
print(json.dumps(sorted({e.data["dispatcher"].py_func.__qualname__ for _, e in recorder.buffer})))
"""


def test_volsr_warmup_leaves_nothing_for_a_hosts_first_frames_to_compile(tmp_path):
    """``volsr warmup`` into an empty numba cache; then a host's first frames (VolSR XS at 2x, 4x and stretched, a
    native render, another look and other sizes) compile nothing: numba reports no compilation."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    warmup = subprocess.run([sys.executable, "-m", "volsr_core.cli", "warmup"], capture_output=True, text=True,
                            env=env, timeout=900)
    assert warmup.returncode == 0, warmup.stderr
    assert "VolSR's kernels are in numba's disk cache" in warmup.stdout
    assert any((tmp_path / "numba-cache").rglob("*.nbc")), "the kernels must be in the cache folder given"
    first = subprocess.run([sys.executable, "-c", FIRST_FRAMES], capture_output=True, text=True, env=env, timeout=900)
    assert first.returncode == 0, first.stderr
    assert json.loads(first.stdout) == [], "compiled at a first frame after the warm-up"


ONE_RESAMPLING = """
import numpy as np
from volsr_core.temporal import resample

image = np.random.default_rng(0).random((12, 10, 3), dtype=np.float32)
for width, height in ((20, 24), (30, 36), (25, 17)):  # doubled (a sliding window) and not
    resample.resize_bilinear(image, width, height)
    resample.resize_bicubic(image, width, height, a=-0.75, clamp=(0.0, 1.0))
print(len(resample._resample_kernel.signatures))
"""


def test_resizing_by_two_and_by_other_ratios_compiles_the_resampling_kernel_once():
    """The doubling weights (empty where the ratio is not 2) are read-only as the taps are: a writable empty array
    was another type to numba, and compiled the kernel a second time (the bench's 1/3 size stretch, say)."""
    result = subprocess.run([sys.executable, "-c", ONE_RESAMPLING], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["1"]
