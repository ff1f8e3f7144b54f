"""Pictures people look at: float images to 8 bits, PNG files, labelled side-by-side panels, MP4 videos.

Images are (H, W, 3), row 0 at the top (docs/conventions.md); float ones in [0, 1]. Every file is
written atomically (:mod:`volsr_core.atomic`): an interrupted run leaves complete files only. Pillow
draws and writes PNGs; MP4 needs the video extra (imageio, imageio-ffmpeg: its ffmpeg binary), imported
only when used. The ffmpeg that encodes an MP4 is this process's own child: it dies with it.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
from contextlib import contextmanager
from fractions import Fraction
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np

from volsr_core.atomic import atomic_path, atomic_write
from volsr_core.errors import OutputError, VolSRError

VIDEO_HINT = "install the video extra: pip install 'volsr[video]' (imageio, imageio-ffmpeg)"


def to_uint8(image: np.ndarray) -> np.ndarray:
    """A float image in [0, 1] as uint8, rounded to the nearest level and clipped."""
    return np.clip(np.rint(np.asarray(image, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)


def write_png(path: str | os.PathLike, rgb8: np.ndarray) -> None:
    """Write a uint8 (H, W, 3) image to ``path`` as PNG, atomically."""
    from PIL import Image

    with atomic_write(path) as fh:
        Image.fromarray(rgb8).save(fh, format="PNG")


def labelled(rgb8: np.ndarray, text: str) -> np.ndarray:
    """``rgb8`` with ``text`` in its top-left corner, white on a dark box."""
    from PIL import Image, ImageDraw, ImageFont

    image = Image.fromarray(rgb8)
    size = max(8, min(28, rgb8.shape[0] // 20))
    try:
        font = ImageFont.load_default(size=size)
    except (TypeError, OSError, ImportError):  # Pillow without FreeType: the fixed bitmap font
        font = ImageFont.load_default()
    draw = ImageDraw.Draw(image)
    margin = max(2, size // 3)
    left, top, right, bottom = draw.textbbox((margin, margin), text, font=font)
    draw.rectangle((left - margin // 2, top - margin // 2, right + margin // 2, bottom + margin // 2), fill=(0, 0, 0))
    draw.text((margin, margin), text, fill=(255, 255, 255), font=font)
    return np.asarray(image)


def side_by_side(panels: Sequence[tuple[str, np.ndarray]]) -> np.ndarray:
    """The (label, float image) panels left to right, each labelled: (H, W * len(panels), 3) uint8."""
    return np.concatenate([labelled(to_uint8(image), label) for label, image in panels], axis=1)


def require_video() -> None:
    """Raise a one-line VolSRError unless imageio and imageio-ffmpeg are installed."""
    try:
        import imageio  # noqa: F401
        import imageio_ffmpeg  # noqa: F401
    except ImportError as err:
        raise VolSRError(f"writing MP4 needs {err.name}: {VIDEO_HINT}") from None


PR_SET_PDEATHSIG = 1  # linux/prctl.h


def dies_with_this_process() -> Callable[[], None] | None:
    """A ``preexec_fn`` after which the child gets SIGKILL when this process dies, even by SIGKILL (Linux
    ``prctl(PR_SET_PDEATHSIG)``; strictly, when the thread that started it ends); None where there is none."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes

    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl  # looked up here: the child only calls it
    except (OSError, AttributeError):
        return None
    parent = os.getpid()

    def preexec() -> None:
        prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() != parent:  # the parent died before the request took effect
            os._exit(1)

    return preexec


class FfmpegPipe:
    """ffmpeg encoding the frames given to :meth:`append_data` (uint8 (H, W, 3), all of one size) to H.264 at
    ``path``, from its stdin; started at the first frame. The child stays in this process group and
    :func:`dies_with_this_process`; :meth:`kill` ends it at once. ``name`` is the file errors name."""

    def __init__(self, path: str | os.PathLike, fps: float, name: str | os.PathLike):
        self.path, self.fps, self.name = Path(path), fps, Path(name)
        self.process: subprocess.Popen | None = None
        self.size: tuple[int, int] | None = None
        self._log = tempfile.TemporaryFile()

    def _command(self, width: int, height: int) -> list[str]:
        import imageio_ffmpeg

        # H.264 4:2:0 needs even sizes: odd ones are padded by one pixel, not resized
        pad = ["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"] if width % 2 or height % 2 else []
        return [imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
                "-s", f"{width}x{height}", "-r", str(Fraction(self.fps).limit_denominator()), "-i", "-", "-an",
                "-c:v", "libx264", "-pix_fmt", "yuv420p", "-crf", "10", *pad, str(self.path)]

    def append_data(self, rgb8: np.ndarray) -> None:
        frame = np.ascontiguousarray(rgb8, dtype=np.uint8)
        height, width = frame.shape[:2]
        if self.process is None:
            self.size = (width, height)
            self.process = subprocess.Popen(self._command(width, height), stdin=subprocess.PIPE,
                                            stdout=subprocess.DEVNULL, stderr=self._log,
                                            preexec_fn=dies_with_this_process())
        elif (width, height) != self.size:
            raise ValueError(f"{self.name}: frame of {width}x{height} in a {self.size[0]}x{self.size[1]} video")
        try:
            self.process.stdin.write(frame.tobytes())
        except BrokenPipeError:
            raise self._failure() from None

    def close(self) -> None:
        """Finish the file: ffmpeg gets the end of its input and must exit with status 0."""
        if self.process is None:
            raise OutputError(self.name, "no frames to write")
        try:
            self.process.stdin.close()
        except BrokenPipeError:
            pass
        if self.process.wait() != 0:
            raise self._failure()
        self._log.close()

    def kill(self) -> None:
        """Stop ffmpeg now (writing was abandoned); the file it was writing is left to its owner to delete."""
        if self.process is not None:
            self.process.kill()
            self.process.wait()
            try:
                self.process.stdin.close()
            except BrokenPipeError:
                pass
        self._log.close()

    def _failure(self) -> OutputError:
        """The one-line error of an ffmpeg that stopped: its exit status and the last line it printed."""
        status = self.process.wait()
        self._log.seek(0)
        lines = [line.strip() for line in self._log.read().decode("utf-8", "replace").splitlines() if line.strip()]
        return OutputError(self.name, f"ffmpeg stopped (exit status {status})" + (f": {lines[-1]}" if lines else ""))


@contextmanager
def mp4_writer(path: str | os.PathLike, fps: float = 24.0) -> Iterator[FfmpegPipe]:
    """A writer (``append_data(rgb8)``) for an H.264 MP4 at ``path``, written atomically: the MP4 appears
    whole when the block ends; on any error ffmpeg is killed and the temporary file deleted."""
    require_video()
    with atomic_path(path) as tmp:
        writer = FfmpegPipe(tmp, fps, name=path)
        try:
            yield writer
        except BaseException:
            writer.kill()
            raise
        writer.close()
