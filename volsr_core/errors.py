"""Errors that VolSR reports to people: one line, naming the file and the problem."""
from __future__ import annotations

import errno
import os


class VolSRError(Exception):
    """Base class of every error VolSR reports; the CLI prints ``str(err)`` and exits 2."""


class PathError(VolSRError):
    """An error about one file or folder (or option): ``str(err)`` is ``"<path>: <problem>"`` on one line."""

    def __init__(self, path: str | os.PathLike | None, problem: str):
        self.path = None if path is None else os.fspath(path)
        self.problem = " ".join(str(problem).split())  # always one line
        super().__init__(self.problem if self.path is None else f"{self.path}: {self.problem}")


class InputError(PathError):
    """Bad input: a missing, unreadable, malformed or unsupported file or folder."""


class OutputError(PathError):
    """A file or folder VolSR cannot write: no permission, a read-only file system, a full disk or
    quota, the file-size limit, or a name of the wrong kind (a file where a folder is needed)."""


#: Why a write failed, by errno, in words people act on.
_WRITE_PROBLEMS = {
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file too large (the file-size limit, ulimit -f, is reached)",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted",
}
WRITE_ERRNOS = frozenset(_WRITE_PROBLEMS)  # the errors of a file system that refuses a write


def write_error(path: str | os.PathLike, err: OSError) -> OutputError:
    """The one-line OutputError for an OSError raised while writing ``path``."""
    reason = _WRITE_PROBLEMS.get(err.errno) or err.strerror or type(err).__name__
    return OutputError(path, f"cannot write: {reason}")


def read_text_file(path: str | os.PathLike) -> str:
    """A file's UTF-8 text, or an InputError naming the file and why it cannot be read."""
    from pathlib import Path

    try:
        return Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(path, "no such file") from None
    except IsADirectoryError:
        raise InputError(path, "is a folder, not a file") from None
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(path, f"cannot read as text: {getattr(err, 'strerror', None) or err}") from None


#: The optional extra (setup.py) that installs each optional module VolSR imports.
EXTRAS = {"onnxruntime": "onnx", "onnx": "onnx", "onnxscript": "onnx", "torch": "torch", "skimage": "torch",
          "matplotlib": "torch", "imageio": "video", "imageio_ffmpeg": "video", "vtk": "vtk", "pyvista": "pyvista"}


def require_extra(module: str, purpose: str) -> None:
    """:func:`require` with the message ``"<purpose> needs <module>: pip install 'volsr[<extra>]'"``."""
    require(module, f"{purpose} needs {module}: pip install 'volsr[{EXTRAS[module]}]'")


def require(module: str, message: str) -> None:
    """Raise a one-line VolSRError ``message`` (which names the extra to install) unless ``module``
    can be imported."""
    import importlib.util

    try:
        found = importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent package missing, or an import blocked in sys.modules
        found = False
    if not found:
        raise VolSRError(message)
