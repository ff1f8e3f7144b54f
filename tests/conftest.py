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
def headsq_dicom(shared_data: Path) -> Path:
    return shared_data / "volumes" / "headsq_dicom"


@pytest.fixture(scope="session")
def ct_avm_path(shared_data: Path) -> Path:
    return shared_data / "volumes" / "CT_AVM.nii.gz"
