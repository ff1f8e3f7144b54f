"""The synthetic CT phantom: deterministic, HU per tissue where expected, geometry as documented."""
from __future__ import annotations

import numpy as np
import pytest

from volsr_core.io import VolumeRecord, make_phantom
from volsr_core.io.phantom import phantom_landmarks
from volsr_core.scene import Volume

SMALL = (64, 64, 64)
SMALL_SPACING = (3.0, 3.0, 3.0)


@pytest.fixture(scope="module")
def phantom() -> VolumeRecord:
    return make_phantom(seed=7)


def value_at(record: VolumeRecord, world: np.ndarray) -> float:
    """Voxel value nearest to a world point (identity direction)."""
    i, j, k = np.rint((np.asarray(world) - np.asarray(record.origin)) / np.asarray(record.spacing)).astype(int)
    return float(record.array[k, j, i])


def class_fractions(a: np.ndarray) -> dict[str, float]:
    classes = {"air": (-1000, -1000), "lung": (-950, -750), "fat": (-150, -50), "soft": (0, 100),
               "vessel": (300, 400), "bone": (700, 1300)}
    return {name: float(((a >= lo) & (a <= hi)).mean()) for name, (lo, hi) in classes.items()}


def test_record_geometry_and_metadata(phantom):
    assert isinstance(phantom, VolumeRecord)
    assert phantom.array.shape == (128, 128, 128) and phantom.array.dtype == np.float32
    assert phantom.spacing == (1.5, 1.5, 1.5)
    np.testing.assert_allclose(phantom.origin, [-95.25] * 3)
    np.testing.assert_array_equal(phantom.direction, np.eye(3))
    assert (phantom.modality, phantom.units, phantom.source) == ("CT", "HU", "phantom(seed=7)")
    np.testing.assert_allclose(Volume.from_record(phantom).center, 0.0, atol=1e-9)


def test_anisotropic_shape_and_spacing_centre_the_volume():
    record = make_phantom(seed=1, shape=(40, 48, 56), spacing=(0.8, 1.0, 2.5))
    assert record.array.shape == (40, 48, 56)
    assert record.spacing == (0.8, 1.0, 2.5)
    np.testing.assert_allclose(record.origin, [-0.8 * 55 / 2, -1.0 * 47 / 2, -2.5 * 39 / 2])
    np.testing.assert_allclose(Volume.from_record(record).center, 0.0, atol=1e-9)
    assert 0.01 < class_fractions(record.array)["lung"] < 0.1


def test_same_seed_same_array_other_seed_other_vessels():
    a = make_phantom(seed=3, shape=SMALL, spacing=SMALL_SPACING).array
    b = make_phantom(seed=3, shape=SMALL, spacing=SMALL_SPACING).array
    c = make_phantom(seed=4, shape=SMALL, spacing=SMALL_SPACING).array
    np.testing.assert_array_equal(a, b)
    vessel_a, vessel_c = (a > 300) & (a < 400), (c > 300) & (c < 400)
    assert (vessel_a != vessel_c).sum() > 0.2 * min(vessel_a.sum(), vessel_c.sum())


def test_values_stay_in_the_ct_range(phantom):
    a = phantom.array
    assert np.isfinite(a).all()
    assert a.min() >= -1024 and a.max() <= 3071
    assert a.min() == -1000.0


def test_outside_the_body_is_air(phantom):
    a = phantom.array
    for corner in [(0, 0, 0), (0, 0, -1), (0, -1, 0), (-1, 0, 0), (-1, -1, -1)]:
        assert a[corner] == -1000.0
    assert np.all(a[:, :, :2] == -1000.0) and np.all(a[:, :2, :] == -1000.0) and np.all(a[-2:] == -1000.0)


def test_lung_centres_are_about_minus_850(phantom):
    marks = phantom_landmarks(phantom.array.shape, phantom.spacing)
    for name in ("right_lung", "left_lung"):
        assert abs(value_at(phantom, marks[name]) + 850.0) < 60.0, name
    assert marks["right_lung"][0] < 0 < marks["left_lung"][0], "LPS: the patient's right is -x"


def test_organ_centres_are_soft_tissue(phantom):
    marks = phantom_landmarks(phantom.array.shape, phantom.spacing)
    assert 20.0 < value_at(phantom, marks["brain"]) < 50.0
    assert 40.0 < value_at(phantom, marks["liver"]) < 80.0
    assert marks["brain"][2] > marks["liver"][2], "LPS: the head is at +z"


def test_body_has_skin_fat_and_soft_tissue_layers(phantom):
    # walk from the anterior air into the belly at the liver's height and the midline
    marks = phantom_landmarks(phantom.array.shape, phantom.spacing)
    k = int(round((marks["liver"][2] - phantom.origin[2]) / phantom.spacing[2]))
    profile = phantom.array[k, :, 64]
    entry = int(np.argmax(profile > -1000))
    assert np.all(profile[:entry] == -1000.0)
    depth = profile[entry:entry + 30]
    skin = int(np.argmax((depth > 50) & (depth < 90)))
    fat = int(np.argmax((depth > -110) & (depth < -90)))
    soft = int(np.argmax((depth > 30) & (depth < 60)))
    assert 0 < skin <= 2, f"a skin voxel right under the surface: {depth[:4]}"
    assert skin < fat < soft, f"skin, then subcutaneous fat, then soft tissue: {depth}"
    assert np.all(depth[fat:fat + 4] < -90), "a fat layer several voxels thick"


def test_every_tissue_class_has_a_plausible_share(phantom):
    f = class_fractions(phantom.array)
    assert 0.5 < f["air"] < 0.85
    assert 0.01 < f["lung"] < 0.1
    assert 0.03 < f["fat"] < 0.2
    assert 0.05 < f["soft"] < 0.3
    assert 0.001 < f["vessel"] < 0.02
    assert 0.003 < f["bone"] < 0.05


def test_bone_shell_and_vessels_exist_with_their_hu(phantom):
    a = phantom.array
    bone, vessel = (a >= 700) & (a <= 1300), (a >= 300) & (a <= 400)
    assert bone.sum() > 5000 and vessel.sum() > 3000
    assert a.max() <= 1300, "bone tops out at ~1200 HU"
    # the shell has holes: looking through the chest along y there are bone-free lines of sight
    chest = bone[40:80, :, 30:98].any(axis=1)
    assert 0.2 < chest.mean() < 0.9


def test_lungs_are_textured_not_flat(phantom):
    marks = phantom_landmarks(phantom.array.shape, phantom.spacing)
    i, j, k = np.rint((marks["left_lung"] - np.asarray(phantom.origin)) / 1.5).astype(int)
    core = phantom.array[k - 8:k + 8, j - 8:j + 8, i - 8:i + 8]
    assert np.all((core > -950) & (core < -750))
    assert core.std() > 2.0


def test_scales_with_shape():
    tiny = make_phantom(seed=0, shape=(16, 20, 24), spacing=(6.0, 6.0, 6.0))
    assert tiny.array.shape == (16, 20, 24)
    assert (tiny.array == -1000).any() and (tiny.array > 0).any()
