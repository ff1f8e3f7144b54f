"""`volsr dataset`: config checks, the stores and the manifest, splits, resuming after SIGKILL, shards."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from volsr_core.cli import main
from volsr_core.errors import InputError
from volsr_core.dataset.config import read_config
from volsr_core.temporal.jitter import halton_jitter, jitter_phases
from volsr_core.dataset.videos import generate, load_dataset_volume, plan_videos
from volsr_core.dataset.store import frame_pixels_per_voxel, store_layout, validate_manifest
from volsr_core.scene.camera import Camera

REPO = Path(__file__).resolve().parents[1]
VIDEOS_PER_VOLUME = 3


def tiny_config_text(headsq: str) -> str:
    return f"""\
seed: 7
hr_size: 64
scales: [2, 4]
frames_per_video: 4
previous_frames: 2
ground_truth: {{mode: supersampled, spp: 4}}
camera: {{pool_size: 8, max_orbit_speed: 6.0}}
volumes:
  - name: phantom
    path: phantom
    phantom_shape: [48, 48, 48]
    transfer_function: {{preset: CT-Phantom}}
    videos: {VIDEOS_PER_VOLUME}
  - name: headsq
    path: {headsq}
    transfer_function: {{preset: CT-Bone, range: auto}}
    videos: {VIDEOS_PER_VOLUME}
"""


@pytest.fixture(scope="module")
def config_file(tmp_path_factory, headsq_dicom) -> Path:
    folder = tmp_path_factory.mktemp("config")
    path = folder / "tiny.yaml"
    path.write_text(tiny_config_text(os.path.relpath(headsq_dicom, folder)))  # relative to the config's folder
    return path


@pytest.fixture(scope="module")
def reference(config_file, tmp_path_factory) -> Path:
    """The dataset rendered in one uninterrupted run."""
    out = tmp_path_factory.mktemp("reference")
    generate(read_config(config_file), out, log=lambda text: None, progress=False)
    return out


def checksums(folder: Path) -> dict[str, dict[str, str]]:
    manifest = json.loads((folder / "manifest.json").read_text())
    return {v["id"]: v["checksums"] for v in manifest["videos"]}


def test_manifest_validates_with_schema_and_checksums(reference):
    manifest = validate_manifest(reference / "manifest.json")
    assert manifest["complete"] is True
    assert [v["id"] for v in manifest["videos"]] == [f"v{i:04d}" for i in range(2 * VIDEOS_PER_VOLUME)]
    assert [v["volume"] for v in manifest["videos"]] == ["phantom"] * 3 + ["headsq"] * 3
    assert manifest["config"]["volumes"][1]["path"] == str(Path(manifest["config"]["volumes"][1]["path"]).resolve())
    assert not list(reference.rglob("*.part"))


def test_validate_manifest_catches_a_changed_array(reference, tmp_path):
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(reference, copy)
    with h5py.File(copy / "videos" / "v0004.h5", "r+") as h5:
        h5["lr4/depth"][2, 0, 0] += 0.5
    with pytest.raises(InputError, match=r"v0004: checksum of lr4/depth"):
        validate_manifest(copy / "manifest.json")
    (copy / "videos" / "v0001.h5").unlink()
    with pytest.raises(InputError, match=r"v0001: videos/v0001.h5 does not exist"):
        validate_manifest(copy / "manifest.json")


def test_split_is_by_video_and_deterministic(reference, config_file):
    manifest = json.loads((reference / "manifest.json").read_text())
    splits = manifest["splits"]
    members = [vid for ids in splits.values() for vid in ids]
    assert sorted(members) == sorted(v["id"] for v in manifest["videos"])  # every video in exactly one split
    assert len(members) == len(set(members))
    for volume in ("phantom", "headsq"):  # 3 videos per volume: one each for train, val and test
        ids = {v["id"] for v in manifest["videos"] if v["volume"] == volume}
        assert [len(ids & set(splits[s])) for s in ("train", "val", "test")] == [1, 1, 1]
    assert [p.split for p in plan_videos(read_config(config_file))] == [v["split"] for v in manifest["videos"]]


def test_stores_hold_the_documented_datasets(reference):
    manifest = json.loads((reference / "manifest.json").read_text())
    layout = store_layout(4, (64, 64), (2, 4))
    assert set(layout) == {"hr/color", "cameras"} | {f"lr{s}/{n}" for s in (2, 4) for n in
                                                     ("color", "alpha", "depth", "max_rgba", "motion_depth",
                                                      "centred", "motion", "jitter")}
    for video in manifest["videos"]:
        with h5py.File(reference / video["file"], "r") as h5:
            assert dict(h5.attrs) == {"video": video["id"], "volume": video["volume"], "format": "volsr-video",
                                      "version": 2}
            found = set()
            h5.visititems(lambda name, node: found.add(name) if isinstance(node, h5py.Dataset) else None)
            assert found == set(layout)
            for name, (shape, dtype) in layout.items():
                assert h5[name].shape == shape and h5[name].dtype == dtype, name
            assert h5["hr/color"].chunks == (1, 64, 64, 3) and h5["hr/color"].compression == "gzip"
            hr = h5["hr/color"][:]
            assert 0.0 <= hr.min() and hr.max() <= 1.0 and hr.max() > 0.2
            for s in (2, 4):
                expected = [halton_jitter(t, jitter_phases(s)) for t in range(4)]
                np.testing.assert_allclose(h5[f"lr{s}/jitter"][:], expected, atol=1e-7)
                motion = h5[f"lr{s}/motion"][:]
                assert np.all(motion[0] == 0) and np.all(np.abs(motion[1:]).max(axis=(1, 2, 3)) > 0)  # none at t=0
                depth = h5[f"lr{s}/depth"][:]
                assert depth.min() < 1.0 and depth.max() == 1.0  # background is 1
                motion_depth = h5[f"lr{s}/motion_depth"][:]
                assert np.all(motion_depth[depth == 1.0] == 1.0) and motion_depth.min() < 1.0
                centred, jittered = h5[f"lr{s}/centred"][:], h5[f"lr{s}/color"][:]
                assert centred.shape == jittered.shape and not np.array_equal(centred, jittered), "no jitter there"
            cameras = h5["cameras"][:]
            np.testing.assert_allclose(cameras[:, :3], [c["position"] for c in video["cameras"]])
            assert np.all(cameras[:, 14:] == 0)


def test_frames_pixels_per_voxel_is_the_renderers(config_file, reference):
    """Each video records its volume's smallest spacing; with a frame's camera it gives the renderer's own
    FeatureFrame.pixels_per_voxel at any image height."""
    config = read_config(config_file)
    names = [v.name for v in config.volumes]
    manifest = json.loads((reference / "manifest.json").read_text())
    for video in manifest["videos"][::VIDEOS_PER_VOLUME]:
        source = load_dataset_volume(config, names.index(video["volume"]))
        assert video["voxel_size"] == pytest.approx(min(source.volume.spacing))
        for height in (32, 16):
            rendered = source.caster.render(Camera.from_dict(video["cameras"][2]), height, height).pixels_per_voxel
            assert frame_pixels_per_voxel(video, height)[2] == pytest.approx(rendered, rel=1e-9)
    assert frame_pixels_per_voxel({"cameras": video["cameras"]}, 16) == [None] * len(video["cameras"])


def test_a_run_records_the_voxel_size_of_older_videos_without_rendering(config_file, reference, tmp_path):
    out = tmp_path / "older"
    shutil.copytree(reference, out)
    entry_path = out / "videos" / "v0004.json"
    entry = json.loads(entry_path.read_text())
    recorded = entry.pop("voxel_size")
    entry_path.write_text(json.dumps(entry))
    stores = {p: p.stat().st_mtime_ns for p in (out / "videos").glob("*.h5")}
    lines = []
    manifest = generate(read_config(config_file), out, log=lines.append, progress=False)
    assert any("recorded the voxel size of 1 video(s)" in line for line in lines)
    assert {p: p.stat().st_mtime_ns for p in (out / "videos").glob("*.h5")} == stores
    assert json.loads(entry_path.read_text())["voxel_size"] == recorded
    assert [v["voxel_size"] for v in manifest["videos"] if v["id"] == "v0004"] == [recorded]
    validate_manifest(out / "manifest.json", checksums=False)


def test_sigkill_then_resume_equals_an_uninterrupted_run(config_file, reference, tmp_path):
    out = tmp_path / "killed"
    command = [sys.executable, "-m", "volsr_core.cli", "dataset", str(config_file), "--out", str(out)]
    process = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    videos = out / "videos"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and process.poll() is None:
        if videos.is_dir() and list(videos.glob("v*.json")) and list(videos.glob(".v*.h5.part")):
            process.send_signal(signal.SIGKILL)  # in the middle of writing a store
            break
        time.sleep(0.002)
    process.wait()
    assert process.returncode == -signal.SIGKILL, "the run ended before it could be killed part-way"
    part = sorted(videos.glob(".v*.h5.part"))
    assert part, "the kill should leave a half-written store"
    half_written = part[0].name[1:6]
    manifest = validate_manifest(out / "manifest.json")
    listed = {v["id"] for v in manifest["videos"]}
    assert manifest["complete"] is False and half_written not in listed
    assert listed == {p.stem for p in videos.glob("v*.json")}
    # a store without its JSON (as if killed between the rename and the JSON) is not complete either
    last = "v0005"
    (videos / f"{last}.h5").write_bytes((videos / "v0000.h5").read_bytes())

    result = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert f"{len(listed)} complete, {6 - len(listed)} to render" in result.stdout
    assert not list(out.rglob("*.part"))
    assert validate_manifest(out / "manifest.json")["complete"] is True
    assert checksums(out) == checksums(reference)


def test_shards_partition_the_videos(config_file, reference, tmp_path):
    for i in (0, 1):
        assert main(["dataset", str(config_file), "--out", str(tmp_path / f"shard{i}"), "--shard", f"{i}/2"]) == 0
    ids = [set(checksums(tmp_path / f"shard{i}")) for i in (0, 1)]
    assert ids == [{"v0000", "v0002", "v0004"}, {"v0001", "v0003", "v0005"}]
    assert {**checksums(tmp_path / "shard0"), **checksums(tmp_path / "shard1")} == checksums(reference)
    # the same folder, one shard after the other: complete, and nothing is rendered twice
    same = tmp_path / "same"
    for i in (0, 1):
        assert main(["dataset", str(config_file), "--out", str(same), "--shard", f"{i}/2"]) == 0
    assert validate_manifest(same / "manifest.json")["complete"] is True
    assert checksums(same) == checksums(reference)


def test_a_complete_dataset_is_not_rendered_again(config_file, reference, capsys):
    before = {p: p.stat().st_mtime_ns for p in (reference / "videos").iterdir()}
    assert main(["dataset", str(config_file), "--out", str(reference)]) == 0
    assert "6 complete, 0 to render (0 frames)" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in (reference / "videos").iterdir()} == before


BAD_CONFIGS = [
    ("scales: [2, 4]", "scales: [2, 3]", "scales: 3 is not one of 2, 4, 8, 16"),
    ("hr_size: 64", "hr_size: 66", "hr_size: 66x66 is not divisible by scale 4"),
    ("hr_size: 64", "hr_size: [64]", "hr_size: expected an integer or [width, height]"),
    ("frames_per_video: 4", "frames_per_video: 2", "frames_per_video: must exceed previous_frames (2)"),
    ("seed: 7", "seed: 7\nsede: 3", "sede: unknown key"),
    ("seed: 7\n", "", "seed: missing"),
    ("mode: supersampled", "mode: exact", "ground_truth.mode: must be one of supersampled, taa"),
    ("spp: 4", "spp: 0", "ground_truth.spp: must be at least 1"),
    ("pool_size: 8", "pool_size: 8, zoom_range: [1.2, 2.0]", "camera.zoom_range: must contain 1"),
    ("pool_size: 8", "pool_size: eight", "camera.pool_size: expected an integer"),
    ("preset: CT-Phantom", "preset: CT-Nothing", "volumes[0].transfer_function.preset: no preset 'CT-Nothing'"),
    ("range: auto", "range: [300, 100]", "volumes[1].transfer_function.range: needs low <= high"),
    ("videos: 3\n  - name: headsq", "videos: 0\n  - name: headsq", "volumes[0].videos: must be at least 1"),
    ("name: headsq", "name: phantom", "volumes[1].name: 'phantom' is used twice"),
    ("path: phantom", "path: nowhere.nii.gz", "volumes[0].path:"),
    ("phantom_shape: [48, 48, 48]", "phantom_shape: [48, 48]", "volumes[0].phantom_shape: expected [z, y, x]"),
    ("hr_size: 64", "hr_size: [64, 64", "not valid YAML at line"),
    ("camera: {pool_size: 8, max_orbit_speed: 6.0}", "camera: [8]", "camera: expected a mapping"),
    ("{preset: CT-Phantom}", "{preset: CT-Phantom, name: x}", "transfer_function.name: only applies with 'file'"),
    ("{preset: CT-Phantom}", "{file: none.json}", "volumes[0].transfer_function.file: "),
    ("{preset: CT-Phantom}", "{}", "volumes[0].transfer_function: needs exactly one of 'preset' or 'file'"),
    ("camera: {pool_size: 8,", "camera: {pool_sise: 8,",
     ("camera.pool_sise: unknown key (allowed: pool_size, view_angle, distance_range, max_roll, focal_jitter, "
      "max_orbit_speed, min_orbit_speed, max_elevation_speed, zoom_range, max_elevation, max_zoom_speed, period)")),
    ("spp: 4", "spp: 4, samples: 2", "ground_truth.samples: unknown key (allowed: mode, spp)"),
    ("videos: 3\n  - name: headsq", "videos: 3\n    colour: red\n  - name: headsq",
     "volumes[0].colour: unknown key (allowed: name, path, phantom_shape, transfer_function, videos, split)"),
    ("{preset: CT-Phantom}", "{preset: CT-Phantom, window: 2}",
     "volumes[0].transfer_function.window: unknown key (allowed: preset, file, name, range)"),
    ("videos: 3\n  - name: headsq", "videos: three\n  - name: headsq", "volumes[0].videos: expected an integer"),
    ("pool_size: 8", "pool_size: 8, view_angle: wide", "camera.view_angle: expected a number, got str 'wide'"),
    ("pool_size: 8", "pool_size: 8, view_angle: 0.5", "camera.view_angle: must lie in [1.0, 179.0], got 0.5"),
    ("scales: [2, 4]", "scales: 4", "scales: expected a list, got int 4"),
    ("videos: 3\n  - name: headsq", "videos: 3\n    split: holdout\n  - name: headsq",
     "volumes[0].split: must be one of train, val, test, got 'holdout'"),
]


@pytest.mark.parametrize("old, new, message", BAD_CONFIGS, ids=[m.split(":")[0] for _, _, m in BAD_CONFIGS])
def test_bad_config_exits_2_with_one_line(config_file, tmp_path, capsys, old, new, message):
    text = config_file.read_text()
    assert old in text
    bad = config_file.parent / f"bad_{abs(hash(new))}.yaml"  # beside the good one: relative paths still resolve
    bad.write_text(text.replace(old, new, 1))
    try:
        assert main(["dataset", str(bad), "--out", str(tmp_path / "out")]) == 2
    finally:
        bad.unlink()
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"volsr: error: {bad}: "), err
    assert message in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("shard", ["2/2", "1", "a/b", "1/0"])
def test_bad_shard_exits_2_with_one_line(config_file, tmp_path, capsys, shard):
    assert main(["dataset", str(config_file), "--out", str(tmp_path), "--shard", shard]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--shard: expected i/n" in err


def test_empty_config(tmp_path):
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    with pytest.raises(InputError, match=r"empty.yaml: \(top level\): expected a mapping, got nothing"):
        read_config(empty)


def test_defaults_fill_what_the_config_leaves_out(config_file):
    config = read_config(config_file)
    assert config.pool == {"pool_size": 8, "view_angle": 30.0, "distance_range": [0.9, 1.6], "max_roll": 20.0,
                           "focal_jitter": 0.05}
    assert config.path == {"max_orbit_speed": 6.0, "min_orbit_speed": None, "max_elevation_speed": 1.5,
                           "zoom_range": [0.8, 1.5], "max_elevation": 60.0, "max_zoom_speed": 0.01, "period": 30}
    assert config.volumes[0].phantom_shape == (48, 48, 48) and config.volumes[1].phantom_shape is None
    assert [v.split for v in config.volumes] == [None, None]
    bare = config_file.parent / "bare.yaml"
    bare.write_text(config_file.read_text().replace("ground_truth: {mode: supersampled, spp: 4}\n", "")
                    .replace("    phantom_shape: [48, 48, 48]\n", ""))
    try:
        defaults = read_config(bare)
    finally:
        bare.unlink()
    assert defaults.ground_truth == {"mode": "supersampled", "spp": 16}
    assert defaults.volumes[0].phantom_shape == (128, 128, 128)


def test_transfer_function_from_a_file(shared_data, tmp_path, config_file):
    presets = os.path.relpath(shared_data / "slicer-presets.xml", tmp_path)
    text = config_file.read_text().replace("{preset: CT-Phantom}", f"{{file: {presets}, name: CT-AAA, range: auto}}")
    back = os.path.relpath(config_file.parent, tmp_path)  # headsq's path, written relative to the tiny config
    (tmp_path / "file.yaml").write_text(text.replace("path: ../", f"path: {back}/../"))
    config = read_config(tmp_path / "file.yaml")
    tf = config.volumes[0].transfer_function
    assert tf == {"file": str(shared_data.resolve() / "slicer-presets.xml"), "name": "CT-AAA", "range": "auto"}
    assert config.volumes[0].tf_definition["name"] == "CT-AAA"
    assert config.fingerprint(0, 0) != read_config(config_file).fingerprint(0, 0)


def test_shipped_configs_read(shared_data):
    default = read_config(REPO / "training" / "configs" / "dataset_default.yaml")
    assert default.hr_size == (256, 256) and default.scales == (2, 4, 8)
    assert [v.name for v in default.volumes] == ["phantom", "CT_AVM", "LIDC2"]
    paper = read_config(REPO / "training" / "configs" / "dataset_paper.yaml")
    assert paper.hr_size == (1920, 1920) and paper.scales == (4, 8, 16) and paper.frames_per_video == 100
    assert all(v.videos == 36 for v in paper.volumes)


def test_a_speed_range_draws_each_videos_top_orbit_speed(tmp_path):
    from volsr_core.dataset.config import read_config
    from volsr_core.dataset.videos import camera_path, load_dataset_volume, plan_videos
    from volsr_core.scene.camera import rotation_between

    path = tmp_path / "speeds.yaml"
    path.write_text("""seed: 1
hr_size: 16
scales: [4]
frames_per_video: 12
previous_frames: 0
camera: {pool_size: 4, min_orbit_speed: 0.5, max_orbit_speed: 6.0, max_elevation_speed: 0.0, period: 4}
volumes:
  - {name: phantom, path: phantom, phantom_shape: [16, 16, 16], transfer_function: {preset: CT-Phantom}, videos: 6}
""")
    config = read_config(path)
    source = load_dataset_volume(config, 0)
    tops = []
    for plan in plan_videos(config):
        cameras = camera_path(config, source, plan)
        tops.append(max(rotation_between(a, b) for a, b in zip(cameras, cameras[1:])))
    assert max(tops) <= 6.0 + 1e-6 and min(tops) < 0.6 * max(tops), f"top speeds differ per video: {tops}"
    path.write_text(path.read_text().replace("min_orbit_speed: 0.5, max_orbit_speed: 6.0", "min_orbit_speed: 7.0"))
    with pytest.raises(Exception, match="min_orbit_speed, max_orbit_speed: needs low <= high"):
        read_config(path)



SLAB_VIDEO = """\
seed: 5
hr_size: 32
scales: [4]
frames_per_video: 3
previous_frames: 0
ground_truth: {mode: supersampled, spp: 2}
camera: {pool_size: 4, distance_range: [0.35, 0.45]}
volumes:
  - {name: phantom, path: phantom, phantom_shape: [40, 40, 40], transfer_function: {preset: CT-Phantom}, videos: 1,
     split: train}
"""


def test_depth_slabs_are_stored_beside_the_buffers_a_dataset_without_them_holds(tmp_path):
    """``slabs: K`` adds each scale's K depth slabs, which composite to the frame's colour, and leaves every other
    array (and the fingerprint of a config without it) as it was."""
    from volsr_core.render.layout import SLAB_CHANNELS, SLAB_RGBA

    stores = {}
    for k in (0, 2):
        (tmp_path / f"k{k}.yaml").write_text(SLAB_VIDEO + (f"slabs: {k}\n" if k else ""))
        config = read_config(tmp_path / f"k{k}.yaml")
        assert config.slabs == k
        generate(config, tmp_path / f"set{k}", log=lambda text: None, progress=False)
        stores[k] = h5py.File(tmp_path / f"set{k}" / "videos" / "v0000.h5", "r")
    assert set(stores[2]) == set(stores[0]) and set(stores[2]["lr4"]) == set(stores[0]["lr4"]) | {"slabs"}
    for name in stores[0]["lr4"]:
        assert np.array_equal(stores[2]["lr4"][name][()], stores[0]["lr4"][name][()]), name
    assert np.array_equal(stores[2]["hr/color"][()], stores[0]["hr/color"][()])
    slabs = stores[2]["lr4/slabs"][()]
    assert slabs.shape == (3, 2, 8, 8, SLAB_CHANNELS) and slabs.dtype == np.float32
    rgba = slabs[..., SLAB_RGBA:SLAB_RGBA + 4]
    composite = rgba[:, 0, ..., :3] + (1.0 - rgba[:, 0, ..., 3:]) * rgba[:, 1, ..., :3]  # front to back, over black
    colour = stores[0]["lr4/color"][()].astype(np.float32)
    assert colour.max() > 0.2 and np.abs(composite - colour).max() < 0.02  # rays past early termination: a little more
    assert all(s.any() for s in rgba[..., 3].max(axis=(0, 2, 3)) > 0.05)  # both slabs show something
    assert json.loads((tmp_path / "set2" / "manifest.json").read_text())["config"]["slabs"] == 2
    validate_manifest(tmp_path / "set2" / "manifest.json")
    (tmp_path / "k0b.yaml").write_text(SLAB_VIDEO + "slabs: 0\n")
    fingerprints = [read_config(tmp_path / f"{name}.yaml").fingerprint(0, 0) for name in ("k0", "k0b", "k2")]
    assert fingerprints[0] == fingerprints[1] != fingerprints[2]
