# Two commands on a fresh machine: `make demo` and `make test`. Both create .venv when needed.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-$(shell cat setup.py constraints.txt | sha1sum | cut -c1-12)
export VTK_DEFAULT_OPENGL_WINDOW ?= vtkEGLRenderWindow

.PHONY: demo test bench env clean

$(STAMP):
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e ".[dev,vtk,torch,onnx]"
	rm -f $(VENV)/.installed-*
	touch $(STAMP)

env: $(STAMP)

## the main job on the embedded default data: an orbit of the synthetic CT phantom, as PNG frames
demo: $(STAMP)
	$(BIN)/volsr info
	$(BIN)/volsr render --orbit 12 --size 384 --out out/demo --features
	$(BIN)/volsr render --size 512 --spp 16 --elevation 20 --out out/demo/phantom_16spp.png

## the test suite (the data in ../shared/data is used when present; under CI=true it must be)
test: $(STAMP)
	$(BIN)/python -m pytest -q

## renderer vs VTK's CPU ray caster on the shared volumes (not part of the tests)
bench: $(STAMP)
	$(BIN)/python benchmarks/bench_renderer.py

## numba caches kernels on disk keyed by the file that defines the kernel: after editing a file a
## kernel inlines from (render/stages.py, temporal/color.py), clear them
clean:
	rm -rf out .pytest_cache
	find volsr_core -name '*.nbi' -o -name '*.nbc' | xargs -r rm -f
