"""Package shape: the core imports without the extras, imports flow down the layer list, and importing it sets how long
numba's idle OpenMP threads spin."""
from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "volsr_core"
LAYERS = ["io", "scene", "render", "temporal", "dataset", "sr", "runtime", "hosts", "apps", "cli"]
SHARED = {"errors", "atomic", "hashing", "images", "_vtk", "config_reader"}  # plain helpers every layer may use


def layer_of(module: str) -> str | None:
    parts = module.split(".")
    if parts[0] != "volsr_core" or len(parts) < 2:
        return None
    return parts[1]


def test_core_imports_without_vtk_torch_or_onnxruntime():
    code = ("import sys, volsr_core.io, volsr_core.scene, volsr_core.render, volsr_core.temporal, volsr_core.dataset,"
            " volsr_core.dataset.videos, volsr_core.sr.history, volsr_core.apps.upscale, volsr_core.cli;"
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('vtk', 'vtkmodules', 'torch', 'onnxruntime'));"
            "print(bad); sys.exit(1 if bad else 0)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, f"core import pulled in: {result.stdout}{result.stderr}"


def _spin_count_libgomp_reads(**env: str) -> str:
    """The GOMP_SPINCOUNT libgomp prints when it loads (OMP_DISPLAY_ENV=VERBOSE) in a process that imports volsr_core
    and runs one of its parallel kernels, under ``env``."""
    code = ("import numba, numpy as np, volsr_core; from volsr_core.temporal.resample import resize_bilinear;"
            "resize_bilinear(np.zeros((8, 8, 3), np.float32), 16, 16); print(numba.threading_layer())")
    base = {k: v for k, v in os.environ.items() if k not in ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY")}
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            env={**base, "OMP_DISPLAY_ENV": "VERBOSE", **env}, check=True)
    assert result.stdout.strip() == "omp", f"numba's threading layer is {result.stdout.strip()}, not libgomp's"
    lines = [line for line in result.stderr.splitlines() if "GOMP_SPINCOUNT" in line]
    assert lines, result.stderr
    return lines[0].split("=")[1].strip().strip("'")


def test_importing_the_package_shortens_libgomps_spin_unless_the_process_set_it():
    import volsr_core
    assert _spin_count_libgomp_reads() == volsr_core.SPIN_COUNT
    assert _spin_count_libgomp_reads(GOMP_SPINCOUNT="7") == "7"


def test_imports_flow_down_the_layer_list():
    offences = []
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE)
        own = rel.parts[0] if len(rel.parts) > 1 else rel.stem
        if own not in LAYERS:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            for name in names:
                other = layer_of(name)
                if other is None or other in SHARED or other == own:
                    continue
                if other not in LAYERS or LAYERS.index(other) > LAYERS.index(own):
                    offences.append(f"{rel}: imports {name}")
    assert not offences, "imports must only reach layers listed before their own:\n" + "\n".join(offences)
