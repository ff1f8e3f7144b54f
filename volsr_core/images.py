"""Pictures people look at: float images to 8 bits, PNG files, labelled side-by-side panels, MP4 videos.

Images are (H, W, 3), row 0 at the top (docs/conventions.md); float ones in [0, 1]. Every file is
written atomically (:mod:`volsr_core.atomic`): an interrupted run leaves complete files only. Pillow
draws and writes PNGs; MP4 needs the video extra (imageio, imageio-ffmpeg), imported only when used.
"""
from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Iterator, Sequence

import numpy as np

from volsr_core.atomic import atomic_path, atomic_write
from volsr_core.errors import VolSRError

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


@contextmanager
def mp4_writer(path: str | os.PathLike, fps: float = 24.0) -> Iterator:
    """An imageio writer (``append_data(rgb8)``) for an H.264 MP4 at ``path``, written atomically."""
    require_video()
    import imageio.v2 as imageio

    with atomic_path(path) as tmp:
        # macro_block_size=2: H.264 4:2:0 needs even sizes; odd ones are padded by one pixel, not resized to x16
        writer = imageio.get_writer(tmp, format="FFMPEG", mode="I", fps=fps, codec="libx264", quality=8,
                                    macro_block_size=2, ffmpeg_log_level="error")
        try:
            yield writer
        finally:
            writer.close()
