"""Atomic file writes: write to a temporary name beside the target, then rename over it (a file object, or a
path for writers that need a file name). A write the file system refuses (no permission, read-only, full,
over the file-size limit) becomes a one-line :class:`~volsr_core.errors.OutputError` naming the target,
and the temporary file is removed."""
from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Iterator

from volsr_core.errors import WRITE_ERRNOS, write_error


@contextmanager
def refused_writes_named(path: str | os.PathLike, *temporary: str | os.PathLike) -> Iterator[None]:
    """Turn an OSError of a refused write (:data:`~volsr_core.errors.WRITE_ERRNOS`) about ``path``, one of
    its ``temporary`` names, or no file at all into an OutputError naming ``path``; others pass unchanged."""
    names = {None, os.fspath(path), *(os.fspath(t) for t in temporary)}
    try:
        yield
    except OSError as err:
        if err.errno not in WRITE_ERRNOS or err.filename not in names:
            raise
        raise write_error(path, err) from None


def _temporary(path: Path, prefix: str, suffix: str) -> tuple[int, str]:
    """mkstemp beside ``path`` (``<prefix>XXXXXXXX<suffix>``); a refused write names ``path``."""
    try:
        return tempfile.mkstemp(prefix=prefix, suffix=suffix, dir=path.parent)
    except OSError as err:
        if err.errno not in WRITE_ERRNOS:
            raise
        raise write_error(path, err) from None


def _usual_permissions(tmp: str) -> None:
    """mkstemp makes 0600; give the file the permissions a plain ``open`` would."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)


@contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "wb", **open_kwargs) -> Iterator[IO]:
    """Open a temporary file next to ``path``; on success rename it to ``path``, else delete it.

    Nobody ever sees a half-written ``path``: readers get the old file or the whole new one.
    """
    path = Path(path)
    fd, tmp = _temporary(path, f".{path.name}.", ".part")
    try:
        with refused_writes_named(path, tmp):
            _usual_permissions(tmp)
            with os.fdopen(fd, mode, **open_kwargs) as fh:
                yield fh
            os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path beside ``path`` (same suffix, so writers that go by the extension work) for a
    writer that needs a file name; renamed to ``path`` on success, deleted on any failure."""
    path = Path(path)
    fd, tmp = _temporary(path, f".{path.stem}.", f".part{path.suffix}")
    os.close(fd)
    try:
        with refused_writes_named(path, tmp):
            yield Path(tmp)
            _usual_permissions(tmp)
            os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def stale_parts(path: str | os.PathLike) -> list[Path]:
    """The temporary files that :func:`atomic_write` or :func:`atomic_path` of ``path`` leave behind
    when a run is killed before it can delete them; ``path``'s name may be a glob pattern (``frame_*.png``)."""
    path = Path(path)
    return sorted({*path.parent.glob(f".{path.name}.*.part"), *path.parent.glob(f".{path.stem}.*.part{path.suffix}")})
