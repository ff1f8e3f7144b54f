"""One reader for VolSR's configs: a mapping (YAML, JSON) into a frozen dataclass, checked.

Each config is a tree of frozen dataclasses, one per section. :func:`read_dataclass` builds one
from a mapping: it refuses unknown keys, naming the allowed ones; checks every value against its
field's type hint; fills the fields' defaults; and turns every problem, the dataclass's own
``__post_init__`` ``ValueError`` included, into a one-line
:class:`~volsr_core.errors.InputError` ``"<file>: <key path>: <problem>"`` (e.g.
``train.stepz: unknown key (allowed: steps, ...)``).

Type hints it reads: ``bool``, ``int``, ``float`` (integers are taken), ``str`` (not empty),
``Any`` (unchecked), ``Literal[...]``, ``X | None``, ``tuple[X, ...]``, ``tuple[X, Y]``,
``list[X]`` and nested dataclasses (a section: left out or empty, it takes its defaults and
names its own required keys as missing).
:func:`setting` adds bounds to a field.
"""
from __future__ import annotations

import os
import types
from dataclasses import MISSING, Field, field, fields, is_dataclass
from pathlib import Path
from typing import Any, Literal, Mapping, NoReturn, TypeVar, Union, get_args, get_origin, get_type_hints

import yaml

from volsr_core.errors import InputError, read_text_file

T = TypeVar("T")
Source = str | os.PathLike | None


def setting(default: Any = MISSING, *, low: float | None = None, high: float | None = None,
            expected: str | None = None) -> Any:
    """A dataclass field (``default``: none means required) whose numbers, and the numbers in its
    lists, must lie in [``low``, ``high``]; ``expected`` says what the field takes, in its type
    error (instead of the type hint's wording) and its missing-key error."""
    return field(default=default, metadata={"low": low, "high": high, "expected": expected})


def fail(source: Source, key: str, problem: str) -> NoReturn:
    """Raise the one-line InputError ``"<source>: <key>: <problem>"`` (``(top level)`` for no key)."""
    raise InputError(source, f"{key or '(top level)'}: {problem}")


def read_yaml(path: Path) -> Any:
    """The document in the YAML file at ``path``; a one-line InputError when unreadable or invalid."""
    text = read_text_file(path)
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise InputError(path, f"not valid YAML{where}: {getattr(err, 'problem', None) or err}") from None


def read_dataclass(cls: type[T], value: Any, source: Source, key: str = "") -> T:
    """The dataclass ``cls`` read from the mapping ``value`` found at ``key`` in ``source``."""
    if not isinstance(value, Mapping):
        fail(source, key, f"expected a mapping, got {_kind(value)}")
    known: dict[str, Field] = {f.name: f for f in fields(cls) if f.init}
    unknown = [k for k in value if k not in known]
    if unknown:
        fail(source, _join(key, unknown[0]), f"unknown key (allowed: {', '.join(known)})")
    hints = get_type_hints(cls)
    values: dict[str, Any] = {}
    for name, spec in known.items():
        where = _join(key, name)
        if name in value:
            values[name] = read_value(hints[name], value[name], source, where, **spec.metadata)
        elif is_dataclass(hints[name]):
            values[name] = read_dataclass(hints[name], {}, source, where)
        elif spec.default is MISSING and spec.default_factory is MISSING:
            expected = spec.metadata.get("expected")
            fail(source, where, f"missing ({expected})" if expected else "missing")
    try:
        return cls(**values)
    except ValueError as err:  # the dataclass's own checks
        problem = str(err)
    fail(source, key, problem)


def read_value(hint: Any, value: Any, source: Source, key: str, low: float | None = None,
               high: float | None = None, expected: str | None = None) -> Any:
    """``value`` checked against the type hint ``hint`` (lists become the hint's tuple or list);
    ``low``, ``high`` and ``expected`` as for :func:`setting`."""
    origin, args = get_origin(hint), get_args(hint)
    if hint is Any:
        return value
    if origin in (Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return read_value(inner, value, source, key, low, high, expected)
    if is_dataclass(hint):
        return read_dataclass(hint, {} if value is None else value, source, key)
    if origin is Literal:
        if not any(type(value) is type(a) and value == a for a in args):
            fail(source, key, f"must be one of {', '.join(map(str, args))}, got {value!r}")
        return value
    if origin in (tuple, list):
        repeated = origin is list or args[-1:] == (...,)
        if not isinstance(value, (list, tuple)) or not (repeated or len(value) == len(args)):
            fail(source, key, f"expected {expected or _describe(hint)}, got {_kind(value)}")
        items = args[:1] * len(value) if repeated else args
        return origin(read_value(h, v, source, f"{key}[{i}]", low, high) for i, (h, v) in enumerate(zip(items, value)))
    if hint in (bool, str, int, float):
        taken = {bool: bool, str: str, int: int, float: (int, float)}[hint]
        if (isinstance(value, bool) and hint is not bool) or not isinstance(value, taken) or value == "":
            fail(source, key, f"expected {expected or _describe(hint)}, got {_kind(value)}")
        if hint in (int, float):
            _check_bounds(value, source, key, low, high)
        return hint(value)
    raise TypeError(f"read_value cannot check the type hint {hint!r} of '{key}'")


def _check_bounds(value: float, source: Source, key: str, low: float | None, high: float | None) -> None:
    """Numbers out of [low, high] (either may be None: no bound) are an error."""
    if low is not None and high is not None and not low <= value <= high:
        fail(source, key, f"must lie in [{low}, {high}], got {value}")
    if low is not None and value < low:
        fail(source, key, f"must be at least {low}, got {value}")
    if high is not None and value > high:
        fail(source, key, f"must be at most {high}, got {value}")


def _describe(hint: Any) -> str:
    """What a value of ``hint`` is, for the 'expected ...' of a type error."""
    words = {bool: "true or false", str: "a non-empty string", int: "an integer", float: "a number"}
    if hint in words:
        return words[hint]
    origin, args = get_origin(hint), get_args(hint)
    if origin is tuple and args[-1:] != (...,):
        return f"a list of {len(args)}"
    return "a list"


def _join(key: str, name: Any) -> str:
    return f"{key}.{name}" if key else str(name)


def _kind(value: Any) -> str:
    """A value as error messages show it: its type and repr, shortened."""
    return "nothing" if value is None else f"{type(value).__name__} {value!r}"[:60]
