"""SequenceDataset: item shapes, LR/HR crops that line up, flips that keep the vectors consistent."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch

from volsr_core.sr.loader import SequenceDataset
from volsr_core.dataset.config import read_config
from volsr_core.temporal.jitter import halton_jitter
from volsr_core.temporal.jitter import jitter_phases
from volsr_core.dataset.videos import generate
from volsr_core.temporal.warp import backward_warp

FRAMES = 5

CONFIG = f"""\
seed: 3
hr_size: 64
scales: [2, 4]
frames_per_video: {FRAMES}
previous_frames: 2
ground_truth: {{mode: supersampled, spp: 4}}
camera: {{pool_size: 8, distance_range: [0.55, 0.7], max_orbit_speed: 8.0, max_elevation_speed: 4.0, period: 2}}
volumes:
  - name: checker
    path: checker.nrrd
    transfer_function: {{preset: CT-Bone, range: [0, 1000]}}
    videos: 3
"""


def checker_volume() -> np.ndarray:
    """(z, y, x) = 32^3 float32: 8-voxel blocks alternating 0 and 1000 (air and bone once placed)."""
    k, j, i = np.indices((32, 32, 32)) // 8
    return np.where((i + j + k) % 2 == 0, 1000.0, 0.0).astype(np.float32)


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    import SimpleITK as sitk

    folder = tmp_path_factory.mktemp("checker")
    image = sitk.GetImageFromArray(checker_volume())
    image.SetSpacing((1.0, 1.0, 1.0))
    sitk.WriteImage(image, str(folder / "checker.nrrd"))
    (folder / "config.yaml").write_text(CONFIG)
    generate(read_config(folder / "config.yaml"), folder / "data", log=lambda text: None, progress=False)
    return folder / "data"


@pytest.mark.parametrize("scale, previous, features, crop, channels", [
    (2, 2, ("color", "depth", "max_rgba"), 32, 8),
    (4, 1, ("color", "alpha"), None, 4),
    (2, 0, ("depth",), 16, 1),
    (4, 4, ("max_rgba", "color", "alpha", "depth"), 64, 9),
])
def test_item_shapes_and_dtypes(root, scale, previous, features, crop, channels):
    data = SequenceDataset(root, "train", scale=scale, previous_frames=previous, features=features, crop=crop, seed=0)
    assert len(data) == FRAMES - previous  # one training video (3 videos: 1 train, 1 val, 1 test)
    assert data.channels == channels
    item = data[len(data) - 1]
    p = (crop or 64) // scale
    n = previous + 1
    assert set(item) == {"lr", "motion", "jitter", "hr", "video", "frame"}
    assert item["lr"].shape == (n, channels, p, p)
    assert item["motion"].shape == (n, 2, p, p)
    assert item["jitter"].shape == (n, 2)
    assert item["hr"].shape == (3, p * scale, p * scale)
    for key in ("lr", "motion", "jitter", "hr"):
        assert item[key].dtype == torch.float32
    assert int(item["frame"]) == FRAMES - 1


def test_previous_frames_come_in_order(root):
    data = SequenceDataset(root, "val", scale=4, previous_frames=3, crop=None, augment=False)
    for index in range(len(data)):
        item = data[index]
        t = int(item["frame"])
        expected = [halton_jitter(t - k, jitter_phases(4)) for k in range(4)]  # index k is frame t-k
        np.testing.assert_allclose(item["jitter"].numpy(), expected, atol=1e-7)
        assert torch.all(item["motion"][-1] == 0) == (t == 3)  # frame 0 has no motion


def test_lr_and_hr_crops_line_up(root):
    """The HR crop, box-downsampled by s, matches the LR crop best with no offset."""
    for scale in (2, 4):
        data = SequenceDataset(root, "train", scale=scale, previous_frames=0, crop=32, augment=False,
                               features=("color",), seed=11)
        errors = np.zeros((3, 3))
        origins = set()
        for epoch in range(4):
            data.set_epoch(epoch)
            for index in range(len(data)):
                origins.add(data.draw(index, np.random.default_rng([11, epoch, index]))[0])
                item = data[index]
                lr, hr = item["lr"][0].numpy(), item["hr"].numpy()
                p = lr.shape[-1]
                down = hr.reshape(3, p, scale, p, scale).mean(axis=(2, 4))
                for dy in (-1, 0, 1):
                    for dx in (-1, 0, 1):
                        shifted = down[:, 1 + dy:p - 1 + dy, 1 + dx:p - 1 + dx]
                        errors[dy + 1, dx + 1] += np.mean((lr[:, 1:-1, 1:-1] - shifted) ** 2)
        assert len(origins) > 3, "the crops should start at several LR origins"
        others = np.delete(errors.ravel(), 4)
        assert errors[1, 1] < 0.7 * others.min(), (scale, errors)


def test_flips_mirror_pixels_and_negate_the_right_components(root):
    data = SequenceDataset(root, "train", scale=2, previous_frames=2, crop=48, augment=False)
    base = data.load(1, (3, 5))
    h = data.load(1, (3, 5), hflip=True)
    v = data.load(1, (3, 5), vflip=True)
    assert torch.equal(h["lr"], base["lr"].flip(-1)) and torch.equal(v["lr"], base["lr"].flip(-2))
    assert torch.equal(h["hr"], base["hr"].flip(-1)) and torch.equal(v["hr"], base["hr"].flip(-2))
    assert torch.equal(h["motion"][:, 0], -base["motion"][:, 0].flip(-1))
    assert torch.equal(h["motion"][:, 1], base["motion"][:, 1].flip(-1))
    assert torch.equal(v["motion"][:, 0], base["motion"][:, 0].flip(-2))
    assert torch.equal(v["motion"][:, 1], -base["motion"][:, 1].flip(-2))
    assert torch.equal(h["jitter"], base["jitter"] * torch.tensor([-1.0, 1.0]))
    assert torch.equal(v["jitter"], base["jitter"] * torch.tensor([1.0, -1.0]))


def warp_error(item: dict, motion: torch.Tensor) -> float:
    """Mean |previous LR frame warped with ``motion`` - current LR frame| over valid pixels."""
    current = item["lr"][0, :3].permute(1, 2, 0).numpy()
    previous = item["lr"][1, :3].permute(1, 2, 0).numpy()
    warped, valid = backward_warp(previous, motion.permute(1, 2, 0).numpy())
    return float(np.abs(warped - current)[valid].mean())


def test_flipped_motion_still_warps_the_flipped_frames(root):
    """After a flip the vectors still carry the previous frame onto the current one exactly as well
    as before; leaving the flipped component's sign would warp worse. Each frame is flipped along
    the axis it moves most on (the jitter of the LR frames adds an error floor to every warp)."""
    data = SequenceDataset(root, "train", scale=2, previous_frames=1, crop=None, augment=False)
    right = wrong = 0.0
    for index in range(len(data)):
        base = data.load(index)
        axis = int(base["motion"][0].abs().mean(dim=(1, 2)).argmax())  # 0: x, 1: y
        flipped = data.load(index, hflip=axis == 0, vflip=axis == 1)
        error = warp_error(flipped, flipped["motion"][0])
        assert error == pytest.approx(warp_error(base, base["motion"][0]), rel=1e-4)
        unnegated = flipped["motion"][0].clone()
        unnegated[axis] *= -1
        right, wrong = right + error, wrong + warp_error(flipped, unnegated)
    assert right < 0.8 * wrong


def test_seeded_items_repeat_and_augment_only_flips(root):
    augmented = SequenceDataset(root, "train", scale=4, previous_frames=2, crop=32, augment=True, seed=5)
    plain = SequenceDataset(root, "train", scale=4, previous_frames=2, crop=32, augment=False, seed=5)
    flipped = 0
    for index in range(len(plain)):
        origin, flips = augmented.draw(index, np.random.default_rng([5, 0, index]))
        flipped += any(flips)
        for key, value in augmented[index].items():
            assert torch.equal(value, plain.load(index, origin, *flips)[key]), key
            assert torch.equal(augmented[index][key], value)  # the same seed, epoch and index repeat
        for key, value in plain[index].items():
            assert torch.equal(value, plain.load(index, origin)[key]), key
    assert flipped


def test_dataloader_workers_open_their_own_files(root):
    data = SequenceDataset(root, "train", scale=2, previous_frames=2, crop=32)
    data[0]  # opens a file in this process before the workers fork
    loader = torch.utils.data.DataLoader(data, batch_size=2, num_workers=2)
    batches = list(loader)
    assert sum(len(b["frame"]) for b in batches) == len(data)
    assert batches[0]["lr"].shape == (2, 3, 8, 16, 16)


def test_bad_arguments(root, tmp_path):
    from volsr_core.errors import InputError

    with pytest.raises(InputError, match="manifest.json: missing"):
        SequenceDataset(tmp_path)
    with pytest.raises(InputError, match="scales \\[2, 4\\], not 8"):
        SequenceDataset(root, scale=8, crop=64)
    with pytest.raises(ValueError, match="multiple of the scale"):
        SequenceDataset(root, scale=4, crop=30)
    with pytest.raises(InputError, match="needs at least 6"):
        SequenceDataset(root, previous_frames=5)
    with pytest.raises(ValueError, match="features"):
        SequenceDataset(root, features=("colour",))
    damaged = tmp_path / "damaged"
    shutil.copytree(root, damaged)
    manifest = json.loads((damaged / "manifest.json").read_text())
    manifest["videos"][0]["voxel_size"] = "0.5 mm"
    (damaged / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(InputError) as caught:
        SequenceDataset(damaged, scale=2, crop=32)
    assert str(caught.value) == (f"{damaged / 'manifest.json'}: video {manifest['videos'][0]['id']} has voxel_size "
                                 "'0.5 mm'; expected a positive number of mm")
