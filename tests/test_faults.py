"""Faults and bad input through the real ``volsr`` command, each in a child process (issue 13): unwritable and
full outputs, malformed options, a killed ``upscale --video``, a damaged DICOM file, two trainers on one folder,
a truncated checkpoint, missing optional extras and an unsafe model file.

Every case exits with status 2 (or the documented status), prints no traceback, names the path or option on
the last line of stderr, and leaves no partial output behind.
"""
from __future__ import annotations

import csv
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from test_io import copy_series, files_by_position
from test_training import write_config

REPO = Path(__file__).resolve().parents[1]
SHIPPED_PT = REPO / "resources" / "models" / "volsr-S-4x.pt"
TINY_DATASET = """\
seed: 7
hr_size: 32
scales: [4]
frames_per_video: 3
previous_frames: 1
ground_truth: {mode: supersampled, spp: 2}
camera: {pool_size: 4, max_orbit_speed: 6.0}
volumes:
  - name: phantom
    path: phantom
    phantom_shape: [24, 24, 24]
    transfer_function: {preset: CT-Phantom}
    videos: 3
"""


# -- running the command ------------------------------------------------------------------------------
def volsr(*argv, prefix: tuple[str, ...] = (), file_size_limit: int | None = None, blocked: tuple[str, ...] = (),
          timeout: float = 300) -> subprocess.CompletedProcess:
    """``volsr ARGV`` in a child process (``python -m volsr_core.cli``), optionally behind a command ``prefix``
    (a private mount), under a file-size limit (RLIMIT_FSIZE; SIGXFSZ ignored so that writes fail with
    EFBIG instead of killing the child), or with modules ``blocked`` as if they were not installed."""
    if blocked:
        code = f"import sys; sys.modules.update(dict.fromkeys({list(blocked)!r})); from volsr_core.cli import main; " \
               "sys.exit(main())"
        command = [sys.executable, "-c", code, *map(str, argv)]
    else:
        command = [sys.executable, "-m", "volsr_core.cli", *map(str, argv)]

    def limit_file_size() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (file_size_limit, file_size_limit))

    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run([*prefix, *command], capture_output=True, text=True, timeout=timeout, env=env,
                          preexec_fn=limit_file_size if file_size_limit is not None else None)


def assert_refused(result: subprocess.CompletedProcess, *phrases: str, code: int = 2) -> str:
    """Exit status ``code``, no traceback, and a last stderr line from volsr containing every phrase."""
    assert result.returncode == code, (result.returncode, result.stderr[-3000:])
    assert "Traceback" not in result.stderr, result.stderr[-3000:]
    last = result.stderr.strip().splitlines()[-1]
    assert last.startswith("volsr") and all(phrase in last for phrase in phrases), last
    return last


def leftovers(folder: Path) -> list[Path]:
    """Temporary, partial or hidden files anywhere under ``folder``."""
    return [p for p in folder.rglob("*") if p.name.startswith(".") or ".part" in p.name]


def tmpfs_prefix(folder: Path, options: str) -> tuple[str, ...]:
    """A command prefix that runs the command in a private mount namespace with a tmpfs (``options``, e.g.
    ``ro`` or ``size=64k``) on ``folder``; nothing outside the child sees the mount."""
    script = 'mount -t tmpfs -o "$1" tmpfs "$0" && shift && exec "$@"'
    return ("unshare", "--mount", "--propagation", "private", "sh", "-c", script, str(folder), options)


@pytest.fixture(scope="module")
def mounts(tmp_path_factory) -> None:
    """Skip unless this machine lets the tests mount a tmpfs in a private mount namespace (root, unshare)."""
    if shutil.which("unshare") is None:
        pytest.skip("unshare (util-linux) is not installed: no private tmpfs mounts")
    probe = tmp_path_factory.mktemp("probe")
    result = subprocess.run([*tmpfs_prefix(probe, "ro"), "true"], capture_output=True, text=True)
    if result.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs in a private mount namespace here: {result.stderr.strip()}")


@pytest.fixture(scope="module")
def dataset_config(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("dataset_config") / "tiny.yaml"
    path.write_text(TINY_DATASET)
    return path


@pytest.fixture(scope="module")
def compiled(tmp_path_factory, dataset_config) -> None:
    """The commands the file-size limits below stop run once unlimited first, so that their kernels are compiled
    and in numba's on-disk cache: a cold cache is written on the first run (tens of KB, next to the sources), which
    a limit of a few KB stops before the output the tests are about (under pytest-xdist these tests can come
    before any other test compiled them)."""
    out = tmp_path_factory.mktemp("compiled")
    for argv in (["render", "--size", "16", "--orbit", "2", "--features", "--out", out / "frames"],
                 ["upscale", "--size", "32", "--orbit", "2", "--out", out / "up", "--video", out / "up" / "up.mp4"],
                 ["dataset", dataset_config, "--out", out / "data"]):
        result = volsr(*argv)
        assert result.returncode == 0, result.stderr[-3000:]


# -- outputs that cannot be written ---------------------------------------------------------------------
def outputs_under(root: Path, dataset_config: Path) -> list[tuple[list, Path]]:
    """(argv, the path the error must name) of every command writing into ``root``, which is unwritable."""
    return [
        (["render", "--size", "16", "--out", root / "view.png"], root / "view.png"),
        (["render", "--size", "16", "--orbit", "2", "--out", root / "frames"], root / "frames"),
        (["dataset", dataset_config, "--out", root / "data"], root / "data"),
        (["eval", SHIPPED_PT, "--data", root / "data", "--out", root / "eval"], root / "eval"),
        (["bench", "--size", "16", "--frames", "2", "--warmup", "0", "--out", root / "bench"], root / "bench"),
        (["upscale", "--size", "16", "--orbit", "1", "--out", root / "up"], root / "up"),
    ]


def test_a_read_only_file_system_is_named_before_any_work(tmp_path, mounts, dataset_config):
    root = tmp_path / "ro"
    root.mkdir()
    for argv, named in outputs_under(root, dataset_config):
        assert_refused(volsr(*argv, prefix=tmpfs_prefix(root, "ro")), f"{named}: cannot write: read-only file system")
    # upscale's video: the error names the MP4, not the input volume, and no frame was rendered first
    result = volsr("upscale", "--size", "16", "--orbit", "1", "--out", tmp_path / "up", "--video", root / "up.mp4",
                   prefix=tmpfs_prefix(root, "ro"))
    assert_refused(result, f"{root / 'up.mp4'}: cannot write: read-only file system")
    assert not (tmp_path / "up").exists()


def test_a_read_only_folder_by_permissions(tmp_path, dataset_config):
    if os.geteuid() == 0:
        pytest.skip("running as root, whom chmod does not stop from writing; the read-only mount test covers it")
    root = tmp_path / "locked"
    root.mkdir()
    root.chmod(0o555)
    try:
        for argv, named in outputs_under(root, dataset_config):
            assert_refused(volsr(*argv), f"{named}: cannot write: permission denied")
        assert list(root.iterdir()) == []
    finally:
        root.chmod(0o755)


def test_a_full_disk_during_render_leaves_no_partial_file(tmp_path, compiled):
    out = tmp_path / "out"
    out.mkdir()
    assert_refused(volsr("render", "--size", "64", "--out", out / "view.png", file_size_limit=1000),
                   f"{out / 'view.png'}: cannot write: file too large")
    result = volsr("render", "--size", "64", "--orbit", "2", "--features", "--out", out / "frames",
                   file_size_limit=3000)
    assert_refused(result, str(out / "frames" / "frame_0000"), "cannot write: file too large")
    assert [p for p in out.rglob("*") if p.is_file()] == []


def test_a_full_disk_during_dataset_is_one_line_and_the_next_run_completes(tmp_path, dataset_config, compiled):
    from volsr_core.dataset.store import validate_manifest

    out = tmp_path / "data"
    result = volsr("dataset", dataset_config, "--out", out, file_size_limit=4000)  # h5py used to segfault here
    assert_refused(result, f"{out / 'videos' / 'v0000.h5'}: cannot write: file too large")
    assert leftovers(out) == [] and not list(out.rglob("*.h5"))
    assert volsr("dataset", dataset_config, "--out", out).returncode == 0
    assert len(validate_manifest(out / "manifest.json")["videos"]) == 3


def test_a_dataset_that_cannot_fit_is_refused_before_rendering(tmp_path, mounts, dataset_config):
    out = tmp_path / "small"
    out.mkdir()
    result = volsr("dataset", dataset_config, "--out", out / "data", prefix=tmpfs_prefix(out, "size=64k"))
    assert_refused(result, f"{out / 'data'}: not enough free space: 3 videos need about")


def test_a_full_disk_during_upscale_stops_the_batch(tmp_path, compiled):
    out = tmp_path / "up"
    result = volsr("upscale", "--size", "32", "--orbit", "2", "--out", out, "--video", out / "movie.mp4",
                   file_size_limit=500)
    assert_refused(result, f"{out / 'phantom' / 'frame_0000.png'}: cannot write: file too large")
    assert leftovers(out) == [] and not list(out.rglob("*.png")) and not list(out.rglob("*.mp4"))


# -- malformed options ------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv, phrase", [
    (["render", "--background", "nan,0,0"], "argument --background: must be R,G,B: three numbers in [0, 1]"),
    (["render", "--background", "2,0"], "argument --background: must be R,G,B"),
    (["render", "--background", "2,0,0"], "argument --background: must be R,G,B"),
    (["render", "--sample-distance", "nan"], "argument --sample-distance: must be a finite number of mm > 0"),
    (["render", "--sample-distance", "-1"], "argument --sample-distance: must be a finite number of mm > 0"),
    (["render", "--sample-distance", "0"], "argument --sample-distance: must be a finite number of mm > 0"),
    (["render", "--sample-distance", "1e-5"], "--sample-distance: 1e-05 mm takes more than 64 samples per voxel"),
    (["render", "--sample-distance", "1e5"], "--sample-distance: 100000 mm is longer than the volume's diagonal"),
    (["render", "--range", "0,inf"], "argument --range: range needs finite LO and HI"),
    (["render", "--degrees", "nan", "--orbit", "2"], "argument --degrees: must be a finite number of degrees"),
    (["render", "--elevation", "nan"], "argument --elevation: must be a finite number of degrees in [-90, 90]"),
    (["render", "--size", "100000x100000"], "argument --size: size must be W or WxH with sides of 1 to 8192"),
    (["render", "--spp", "0"], "argument --spp: must be an integer >= 1"),
    (["upscale", "--fps", "inf"], "argument --fps: must be a finite number of frames per second in (0, 240]"),
    (["upscale", "--scale", "0"], "argument --scale: must be an integer in [2, 16]"),
    (["upscale", "--variant", "L"], "no shipped model for variant L at 2x (shipped:"),
    (["bench", "--frames", "0"], "argument --frames: must be an integer >= 1"),
])
def test_malformed_options_exit_2_naming_the_option(tmp_path, argv, phrase):
    out = tmp_path / ("view.png" if argv[0] == "render" else "out")
    size = [] if "--size" in argv else ["--size", "16"]
    assert_refused(volsr(*argv, *size, "--out", out), phrase)
    assert not out.exists()


def test_render_writes_png_only_and_never_makes_a_folder_of_an_image_name(tmp_path):
    assert_refused(volsr("render", "--size", "16", "--out", tmp_path / "view.jpg"),
                   f"{tmp_path / 'view.jpg'}: volsr render writes PNG only; name a .png file or a folder")
    assert_refused(volsr("upscale", "--size", "16", "--out", tmp_path / "up.png"),
                   f"{tmp_path / 'up.png'}: names a .png file; --out takes a folder")
    assert list(tmp_path.iterdir()) == []


# -- upscale owns its ffmpeg ------------------------------------------------------------------------------
def children(pid: int) -> list[int]:
    return [int(p) for p in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]


def is_running(pid: int) -> bool:
    """True while ``pid`` runs (a zombie, dead but not yet reaped by its new parent, does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux /proc to find the ffmpeg child")
def test_sigkill_of_upscale_video_kills_ffmpeg_and_the_next_run_cleans_up(tmp_path):
    out = tmp_path / "up"
    command = [sys.executable, "-m", "volsr_core.cli", "upscale", "--orbit", "240", "--degrees", "2", "--size", "32",
               "--out", str(out), "--video", str(out / "movie.mp4")]
    run = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        deadline = time.monotonic() + 180
        while not (out / "phantom" / "frame_0003.png").exists() and run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        ffmpeg = [pid for pid in children(run.pid) if "ffmpeg" in Path(f"/proc/{pid}/comm").read_text()]
        assert ffmpeg, "upscale --video runs ffmpeg as its child"
    finally:
        run.kill()
        run.wait()
    deadline = time.monotonic() + 10
    while any(is_running(pid) for pid in ffmpeg) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(is_running(pid) for pid in ffmpeg), "ffmpeg outlived the upscale that started it"
    assert leftovers(out), "the killed run left its temporary MP4 (and so the next run has something to clean)"
    result = volsr("upscale", "--orbit", "2", "--size", "32", "--out", out, "--video", out / "movie.mp4")
    assert result.returncode == 0, result.stderr[-3000:]
    assert leftovers(out) == []
    assert sorted(p.name for p in (out / "phantom").iterdir()) == ["frame_0000.png", "frame_0001.png"]
    assert (out / "movie.mp4").stat().st_size > 0


# -- a damaged file in a DICOM series ---------------------------------------------------------------------
def test_a_truncated_dicom_file_is_named_and_resample_says_what_it_filled(tmp_path, headsq_dicom):
    folder = tmp_path / "headsq"
    copy_series(headsq_dicom, folder)
    ordered = files_by_position(folder)
    victim = ordered[40]
    victim.write_bytes(victim.read_bytes()[:100])  # cut inside the preamble: no DICOM magic left
    assert_refused(volsr("render", folder, "--size", "16", "--out", tmp_path / "view.png"),
                   f"{victim}: named .dcm but without a DICOM header (100 bytes; truncated?)", "--resample")
    assert not (tmp_path / "view.png").exists()
    result = volsr("render", folder, "--resample", "--size", "16", "--out", tmp_path / "view.png")
    assert result.returncode == 0, result.stderr
    notes = [line for line in result.stderr.splitlines() if line.startswith("volsr: note:")]
    assert f"skipped 1 damaged file: {victim.name}" in notes[0]
    assert f"filled slice 40 between {ordered[39].name} and {ordered[41].name} (3 mm gap)" in notes[1]


# -- training: one trainer per folder, resume from the newest readable checkpoint -------------------------
def log_steps(run: Path) -> list[int]:
    with (run / "log.csv").open() as fh:
        return [int(row["step"]) for row in csv.DictReader(fh)]


def test_a_second_trainer_on_one_folder_is_refused(tmp_path, tiny_sequences):
    config = write_config(tmp_path, tiny_sequences, steps=100000, checkpoint_every=100000)
    lock = tmp_path / "run" / "train.lock"
    first = subprocess.Popen([sys.executable, "-m", "volsr_core.cli", "train", str(config)],
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        deadline = time.monotonic() + 180
        while not (tmp_path / "run" / "log.csv").exists() and first.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert first.poll() is None and lock.read_text().strip() == str(first.pid)
        second = volsr("train", config)
    finally:
        first.kill()
        first.wait()
    assert_refused(second, f"{lock}: another volsr train (pid {first.pid}) is training into {tmp_path / 'run'}")
    steps = log_steps(tmp_path / "run")
    assert steps == list(range(1, len(steps) + 1)), "only the first trainer wrote log rows"


def test_a_truncated_last_checkpoint_falls_back_to_the_newest_readable_one(tmp_path, tiny_sequences):
    config = write_config(tmp_path, tiny_sequences, steps=4, checkpoint_every=2)
    assert volsr("train", config).returncode == 0
    checkpoints = tmp_path / "run" / "checkpoints"
    last = checkpoints / "last.pt"
    last.write_bytes(last.read_bytes()[:2000])
    write_config(tmp_path, tiny_sequences, steps=6, checkpoint_every=2)
    result = volsr("train", config)
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr[-3000:]
    said = next(line for line in result.stderr.splitlines() if line.startswith("volsr train:"))
    assert f"{last}: not a readable PyTorch checkpoint" in said and "resumed from step_0000004.pt (step 4)" in said
    assert log_steps(tmp_path / "run") == [1, 2, 3, 4, 5, 6]
    for path in checkpoints.glob("*.pt"):  # nothing readable left: refuse, never start over silently
        path.write_bytes(b"damaged")
    write_config(tmp_path, tiny_sequences, steps=8, checkpoint_every=2)
    assert_refused(volsr("train", config), f"{checkpoints}: no readable checkpoint to resume from")


# -- optional extras and unsafe model files ---------------------------------------------------------------
@pytest.mark.parametrize("argv, blocked, phrase", [
    (["upscale", "--size", "16", "--orbit", "1"], ("onnxruntime",), "pip install 'volsr[onnx]'"),
    (["upscale", "--size", "16", "--orbit", "1", "--model", SHIPPED_PT], ("torch",), "pip install 'volsr[torch]'"),
    (["upscale", "--size", "16", "--orbit", "1", "--reference-spp", "2"], ("skimage",), "pip install 'volsr[torch]'"),
    (["upscale", "--size", "16", "--orbit", "1", "--video", "{out}/v.mp4"], ("imageio_ffmpeg",),
     "pip install 'volsr[video]'"),
    (["eval", SHIPPED_PT, "--data", "{out}"], ("torch",), "volsr eval needs torch: pip install 'volsr[torch]'"),
    (["train", "config.yaml"], ("torch",), "volsr train needs torch: pip install 'volsr[torch]'"),
    (["bench", "--size", "16"], ("onnxruntime",), "pip install 'volsr[onnx]'"),
])
def test_a_missing_extra_is_one_line_naming_what_to_install(tmp_path, argv, blocked, phrase):
    argv = [str(a).replace("{out}", str(tmp_path)) for a in argv]
    if argv[0] != "train":
        argv += ["--out", str(tmp_path / "out")]
    assert_refused(volsr(*argv, blocked=blocked), phrase)
    assert not (tmp_path / "out").exists()


def test_an_unsafe_model_file_is_refused_whole_and_never_run(tmp_path):
    torch = pytest.importorskip("torch")
    marker = tmp_path / "ran"

    class Payload:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    evil = tmp_path / "evil.pt"
    torch.save({"format": "volsr-model", "payload": Payload()}, evil)
    for argv in (["eval", evil, "--data", tmp_path, "--out", tmp_path / "eval"],
                 ["upscale", "--model", evil, "--size", "16", "--orbit", "1", "--out", tmp_path / "up"]):
        result = volsr(*argv)
        line = assert_refused(result, f"{evil}: refused: it holds pickled Python objects that loading would run",
                              "GLOBAL posix.system", "VolSR loads only plain tensors and numbers")
        assert line.endswith("numbers") and result.stderr.strip().splitlines() == [line]
    assert not marker.exists()
