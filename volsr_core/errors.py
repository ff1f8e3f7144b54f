"""Errors that VolSR reports to people: one line, naming the file and the problem."""
from __future__ import annotations

import os


class VolSRError(Exception):
    """Base class of every error VolSR reports; the CLI prints ``str(err)`` and exits 2."""


class InputError(VolSRError):
    """Bad input: a missing, unreadable, malformed or unsupported file or folder.

    ``str(err)`` is ``"<path>: <problem>"`` on one line.
    """

    def __init__(self, path: str | os.PathLike | None, problem: str):
        self.path = None if path is None else os.fspath(path)
        self.problem = " ".join(str(problem).split())  # always one line
        super().__init__(self.problem if self.path is None else f"{self.path}: {self.problem}")


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


def require(module: str, message: str) -> None:
    """Raise a one-line VolSRError ``message`` (which names the extra to install) unless ``module``
    can be imported."""
    import importlib.util

    if importlib.util.find_spec(module) is None:
        raise VolSRError(message)
