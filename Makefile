# Two commands on a fresh machine: `make demo` and `make test`. Both create .venv when needed.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-$(shell cat setup.py constraints.txt | sha1sum | cut -c1-12)
export VTK_DEFAULT_OPENGL_WINDOW ?= vtkEGLRenderWindow

.PHONY: demo test bench env paraview-env clean

$(STAMP):
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e ".[dev,vtk,pyvista,torch,onnx,video]"
	$(BIN)/volsr warmup  # numba's kernels compiled once, with a progress bar, not inside the first frame
	rm -f $(VENV)/.installed-*
	touch $(STAMP)

env: $(STAMP)

## .venv-paraview: the venv ParaView's pvpython runs our package in (docs/paraview.md). Debian's Python 3.11 (the one
## pvpython embeds) with its system site-packages: ParaView, its VTK and Debian's numpy 1.24 (constraints-paraview.txt
## overrides the numpy pin); our package and onnxruntime on top; never a pip vtk. `make test` builds it when pvpython exists.
PV_PYTHON ?= /usr/bin/python3
PV_VENV   := .venv-paraview
PV_STAMP  := $(PV_VENV)/.installed-$(shell cat setup.py constraints.txt constraints-paraview.txt | sha1sum | cut -c1-12)
PVPYTHON  := $(shell command -v pvpython 2>/dev/null)

$(PV_STAMP):
	$(PV_PYTHON) -m venv --system-site-packages $(PV_VENV)
	$(PV_VENV)/bin/python -m pip install --quiet --upgrade pip
	{ grep -v '^numpy==' constraints.txt; cat constraints-paraview.txt; } > $(PV_VENV)/constraints.txt
	$(PV_VENV)/bin/python -m pip install --quiet -c $(PV_VENV)/constraints.txt -e ".[video]" onnxruntime
	! ls -d $(PV_VENV)/lib/python3*/site-packages/vtkmodules 2>/dev/null  # ParaView's own VTK only
	rm -f $(PV_VENV)/.installed-*
	touch $(PV_STAMP)

paraview-env: $(PV_STAMP)

## the main job on the embedded default data: an orbit of the synthetic CT phantom (2 degrees per frame, as a
## user drags, the phantom filling the view) rendered at 256x256 and upscaled 2x by the shipped XS model (what
## pays off on a CPU: docs/performance.md); side-by-side (native 1 spp | native 1/2 size + bilinear | VolSR) PNGs
## and MP4, and out/demo/summary.md: ms per frame of each method beside its PSNR against an 8-spp native render
demo: $(STAMP)
	$(BIN)/volsr info
	$(BIN)/volsr upscale --orbit 24 --degrees 2 --size 512 --scale 2 --variant XS --side-by-side --video out/demo/phantom.mp4 \
		--reference-spp 8 --out out/demo
	cat out/demo/summary.md

## the test suite (the data in ../shared/data is used when present; under CI=true it must be)
test: $(STAMP) $(if $(PVPYTHON),$(PV_STAMP))
	$(BIN)/python -m pytest -q

## renderer vs VTK's CPU ray caster on the shared volumes (not part of the tests)
bench: $(STAMP)
	$(BIN)/python benchmarks/bench_renderer.py

## numba caches kernels on disk keyed by the file that defines the kernel: after editing a file a
## kernel inlines from (render/stages.py, temporal/stages.py, temporal/color.py), clear them: make clean
clean:
	rm -rf out .pytest_cache
	find volsr_core -name '*.nbi' -o -name '*.nbc' | xargs -r rm -f
