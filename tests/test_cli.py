"""The `volsr` command end to end: info, render (PNG, .npz features, --spp, camera paths)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from volsr_core.cli import main
from volsr_core.io import make_phantom
from volsr_core.render import RayCaster
from volsr_core.scene import Camera, Volume, get_preset
from volsr_core.scene.camera_paths import orbit, orbit_around, write_camera_path
from volsr_core.temporal import render_supersampled


@pytest.fixture(scope="module")
def phantom() -> Volume:
    return Volume.from_record(make_phantom())


def test_info_on_the_phantom_and_on_dicom(capsys, headsq_dicom):
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    assert "CT (HU)" in out and "128 x 128 x 128 voxels" in out
    assert main(["info", str(headsq_dicom)]) == 0
    out = capsys.readouterr().out
    assert "64 x 64 x 93 voxels" in out and "3.2 x 3.2 x 1.5 mm" in out
    assert "series *" in out and "93 files" in out


def test_render_one_png_equals_the_raycaster(tmp_path, phantom):
    out = tmp_path / "view.png"
    assert main(["render", "--size", "48x32", "--out", str(out)]) == 0
    image = np.asarray(Image.open(out))
    assert image.shape == (32, 48, 3)
    caster = RayCaster(phantom, get_preset("CT-Phantom"))
    camera = orbit_around(caster.visible_bounds(), 1, aspect=48 / 32)[0]  # the visible volume fills the view
    expected = caster.render(camera, 48, 32).to_uint8()
    np.testing.assert_array_equal(image, expected)
    assert image.max() > 100
    assert not list(tmp_path.glob(".*")), "no temporary files may remain"


def test_render_orbit_with_features(tmp_path):
    assert main(["render", "--orbit", "3", "--size", "40", "--features", "--out", str(tmp_path / "frames")]) == 0
    pngs = sorted((tmp_path / "frames").glob("frame_*.png"))
    npzs = sorted((tmp_path / "frames").glob("frame_*.npz"))
    assert [p.name for p in pngs] == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    assert len(npzs) == 3
    with np.load(npzs[1]) as f:
        assert set(f.files) == {"color", "alpha", "depth", "max_rgba", "position", "motion", "motion_depth", "jitter"}
        assert f["color"].shape == (40, 40, 3) and f["motion"].shape == (40, 40, 2)
        assert np.abs(f["motion"]).max() > 1.0  # frame 1 moved 120 degrees from frame 0
    with np.load(npzs[0]) as f:
        assert np.all(f["motion"] == 0)  # no previous frame


def test_render_supersampled(tmp_path, phantom):
    out = tmp_path / "ss.png"
    assert main(["render", "--size", "32", "--spp", "4", "--out", str(out)]) == 0
    caster = RayCaster(phantom, get_preset("CT-Phantom"))
    camera = orbit_around(caster.visible_bounds(), 1)[0]
    expected = render_supersampled(caster, camera, 32, 32, spp=4)
    image = np.asarray(Image.open(out)).astype(np.float32) / 255
    assert np.abs(image - expected).max() <= 0.5 / 255 + 1e-6


def test_render_follows_a_camera_path_file(tmp_path, phantom):
    cameras = orbit(Camera.framing(phantom.bounds, direction=(1, 0, 0)), 2, degrees=90)
    write_camera_path(tmp_path / "path.json", cameras)
    assert main(["render", "--camera-path", str(tmp_path / "path.json"), "--size", "24",
                 "--out", str(tmp_path / "f")]) == 0
    assert len(list((tmp_path / "f").glob("*.png"))) == 2


def test_bad_arguments_exit_2_with_one_line(tmp_path):
    cases = [
        (["render", "--orbit", "3", "--out", str(tmp_path / "one.png")], "names one PNG but 3 frames"),
        (["render", "--preset", "CT-Nope", "--out", str(tmp_path / "x.png")], "CT-Nope"),
        (["render", "--camera-path", str(tmp_path / "missing.json"), "--out", str(tmp_path / "x")], "missing.json"),
        (["render", "--size", "0x5", "--out", str(tmp_path / "x.png")], "size"),
    ]
    for argv, phrase in cases:
        result = subprocess.run([sys.executable, "-m", "volsr_core.cli", *argv], capture_output=True, text=True)
        assert result.returncode == 2, (argv, result.stderr)
        lines = result.stderr.strip().splitlines()
        assert len(lines) >= 1 and phrase in lines[-1] and "Traceback" not in result.stderr, result.stderr
    assert not (tmp_path / "x.png").exists()


def test_render_with_taa_accumulates_over_the_path(tmp_path, phantom):
    from volsr_core.temporal import TemporalAntiAliasing, halton_jitter

    assert main(["render", "--orbit", "4", "--size", "32", "--taa", "--out", str(tmp_path / "taa")]) == 0
    caster, taa, previous = RayCaster(phantom, get_preset("CT-Phantom")), TemporalAntiAliasing(), None
    cameras = orbit_around(caster.visible_bounds(), 4)
    for i, camera in enumerate(cameras):
        frame = caster.render(camera, 32, 32, jitter=halton_jitter(i, 16), previous_camera=previous, seed=i)
        expected, previous = taa(frame.color, frame.motion), camera
    image = np.asarray(Image.open(tmp_path / "taa" / "frame_0003.png")).astype(np.float32) / 255
    assert np.abs(image - expected).max() <= 0.5 / 255 + 1e-6
    assert main(["render", "--taa", "--spp", "4", "--out", str(tmp_path / "x.png")]) == 2
