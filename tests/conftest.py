"""Shared fixtures: the ../shared/data folder (skipped when absent, a failure under CI=true)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("VOLSR_SHARED_DATA", REPO.parent / "shared" / "data"))


def _require_shared() -> Path:
    if SHARED_DATA.is_dir():
        return SHARED_DATA
    message = f"shared data folder {SHARED_DATA} is absent (set VOLSR_SHARED_DATA or put ../shared beside the checkout)"
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(message + "; under CI=true it must be there")
    pytest.skip(message)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path to ../shared/data (volumes/, slicer-presets.xml)."""
    return _require_shared()


@pytest.fixture(scope="session")
def model() -> Path:
    """The shipped VolSR S 4x ONNX file (SHA-256 checked): a trained U-Net, whose every weight shapes its output, for
    tests that need a network file but not a particular one (exporting one takes 15-30 s on the 2-core machine)."""
    pytest.importorskip("onnxruntime")
    from volsr_core.runtime.models import model_file

    return model_file("S", 4, "onnx")


@pytest.fixture(scope="session")
def headsq_dicom(shared_data: Path) -> Path:
    return shared_data / "volumes" / "headsq_dicom"


@pytest.fixture(scope="session")
def ct_avm_path(shared_data: Path) -> Path:
    return shared_data / "volumes" / "CT_AVM.nii.gz"


TINY_SEQUENCES = """\
seed: 3
hr_size: 32
scales: [4]
frames_per_video: 3
previous_frames: 2
ground_truth: {mode: supersampled, spp: 2}
camera: {pool_size: 8, distance_range: [0.35, 0.45]}  # close up: the volume fills the 32-pixel frames
volumes:
  - name: phantom
    path: phantom
    phantom_shape: [40, 40, 40]
    transfer_function: {preset: CT-Phantom}
    videos: 3
"""


@pytest.fixture(scope="session")
def tiny_sequences(tmp_path_factory) -> Path:
    """A dataset of 3 phantom videos x 3 frames at 32² (scale 4), one video per split."""
    from volsr_core.dataset.config import read_config
    from volsr_core.dataset.videos import generate

    folder = tmp_path_factory.mktemp("tiny_sequences")
    (folder / "tiny.yaml").write_text(TINY_SEQUENCES)
    generate(read_config(folder / "tiny.yaml"), folder / "set", log=lambda text: None, progress=False)
    return folder / "set"


@pytest.fixture(scope="session")
def tiny_layered_sequences(tmp_path_factory) -> Path:
    """:func:`tiny_sequences` with each LR frame also in two depth slabs (``slabs: 2``), for the layered TAAU."""
    from volsr_core.dataset.config import read_config
    from volsr_core.dataset.videos import generate

    folder = tmp_path_factory.mktemp("tiny_layered_sequences")
    (folder / "tiny.yaml").write_text(TINY_SEQUENCES + "slabs: 2\n")
    generate(read_config(folder / "tiny.yaml"), folder / "set", log=lambda text: None, progress=False)
    return folder / "set"
