"""Transfer functions: what vtkVolumeProperty holds, as plain numpy.

Piecewise-linear colour (value -> RGB in [0, 1]) and scalar opacity (value -> alpha per
``scalar_opacity_unit_distance`` mm), an optional gradient opacity (gradient magnitude in value
units per mm -> factor), and Blinn-Phong lighting. Outside their points the functions clamp to
the end values, like VTK's defaults (ClampingOn).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np


def _points(values: Any, width: int, what: str) -> np.ndarray:
    pts = np.asarray(values, dtype=np.float64).reshape(-1, width)
    if len(pts) == 0:
        raise ValueError(f"{what} needs at least one point")
    if not np.all(np.isfinite(pts)):
        raise ValueError(f"{what} has non-finite values")
    order = np.argsort(pts[:, 0], kind="stable")
    return pts[order]


def _interp(x: np.ndarray | float, pts: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation of columns 1.. of ``pts`` at x, clamped at both ends."""
    x = np.asarray(x, dtype=np.float64)
    return np.stack([np.interp(x, pts[:, 0], pts[:, c]) for c in range(1, pts.shape[1])], axis=-1)


@dataclass(eq=False)
class TransferFunction:
    """Colour, opacity and lighting for direct volume rendering (VTK's vtkVolumeProperty terms).

    - ``color``: (n, 4) rows (value, r, g, b), r/g/b in [0, 1];
    - ``scalar_opacity``: (m, 2) rows (value, alpha), alpha per ``scalar_opacity_unit_distance`` mm;
    - ``gradient_opacity``: optional (k, 2) rows (gradient magnitude in value units per mm, factor);
    - ``shade``, ``ambient``, ``diffuse``, ``specular``, ``specular_power``: Blinn-Phong, headlight;
    - ``value_range``: the value range the points were designed for (e.g. HU), used when the
      function is placed on another volume's range; defaults to the span of the points.
    """

    color: np.ndarray
    scalar_opacity: np.ndarray
    gradient_opacity: np.ndarray | None = None
    shade: bool = False
    ambient: float = 0.1
    diffuse: float = 0.7
    specular: float = 0.2
    specular_power: float = 10.0
    scalar_opacity_unit_distance: float = 1.0
    name: str = ""
    value_range: tuple[float, float] | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.color = _points(self.color, 4, "color")
        self.scalar_opacity = _points(self.scalar_opacity, 2, "scalar_opacity")
        if self.gradient_opacity is not None:
            self.gradient_opacity = _points(self.gradient_opacity, 2, "gradient_opacity")
        if not self.scalar_opacity_unit_distance > 0:
            raise ValueError("scalar_opacity_unit_distance must be positive")
        if self.value_range is None:
            xs = np.concatenate([self.color[:, 0], self.scalar_opacity[:, 0]])
            self.value_range = (float(xs.min()), float(xs.max()))
        self.value_range = (float(self.value_range[0]), float(self.value_range[1]))

    # evaluation --------------------------------------------------------------------------
    def color_at(self, values: np.ndarray | float) -> np.ndarray:
        """RGB in [0, 1] at the given values, shape (..., 3)."""
        return _interp(values, self.color)

    def opacity_at(self, values: np.ndarray | float) -> np.ndarray:
        """Scalar opacity (per unit distance) at the given values, shape (...)."""
        return _interp(values, self.scalar_opacity)[..., 0]

    def gradient_opacity_at(self, magnitudes: np.ndarray | float) -> np.ndarray:
        """Gradient-opacity factor at gradient magnitudes (value units per mm); 1 when unset."""
        if self.gradient_opacity is None:
            return np.ones_like(np.asarray(magnitudes, dtype=np.float64))
        return _interp(magnitudes, self.gradient_opacity)[..., 0]

    @property
    def has_gradient_opacity(self) -> bool:
        """True when a gradient-opacity function is set and is not constant 1."""
        return self.gradient_opacity is not None and not np.allclose(self.gradient_opacity[:, 1], 1.0)

    # placement ---------------------------------------------------------------------------
    def rescaled(self, source: tuple[float, float], target: tuple[float, float]) -> "TransferFunction":
        """The same function with values mapped linearly from ``source`` onto ``target``.

        Gradient magnitudes scale by the same factor (a gradient is value per mm).
        """
        s0, s1 = map(float, source)
        t0, t1 = map(float, target)
        if s1 == s0:
            raise ValueError("source range is empty")
        k = (t1 - t0) / (s1 - s0)

        def move(pts: np.ndarray) -> np.ndarray:
            out = pts.copy()
            out[:, 0] = t0 + (pts[:, 0] - s0) * k
            return out

        grad = None
        if self.gradient_opacity is not None:
            grad = self.gradient_opacity.copy()
            grad[:, 0] *= abs(k)
        return replace(self, color=move(self.color), scalar_opacity=move(self.scalar_opacity),
                       gradient_opacity=grad, value_range=(t0, t1),
                       metadata=dict(self.metadata))

    def placed_on(self, low: float, high: float) -> "TransferFunction":
        """This function's ``value_range`` mapped onto [low, high] (e.g. a volume's percentiles)."""
        return self.rescaled(self.value_range, (low, high))

    # (de)serialisation ---------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict; the format of ``resources/presets/*.json`` entries."""
        d: dict[str, Any] = {
            "name": self.name,
            "color": self.color.tolist(),
            "scalar_opacity": self.scalar_opacity.tolist(),
            "shade": bool(self.shade),
            "ambient": float(self.ambient),
            "diffuse": float(self.diffuse),
            "specular": float(self.specular),
            "specular_power": float(self.specular_power),
            "scalar_opacity_unit_distance": float(self.scalar_opacity_unit_distance),
            "value_range": list(self.value_range),
        }
        if self.gradient_opacity is not None:
            d["gradient_opacity"] = self.gradient_opacity.tolist()
        if self.metadata:
            d["metadata"] = dict(self.metadata)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "TransferFunction":
        known = {k: d[k] for k in cls.__dataclass_fields__ if k in d}
        unknown = sorted(set(d) - set(cls.__dataclass_fields__))
        if unknown:
            raise ValueError(f"unknown transfer-function keys: {', '.join(unknown)}")
        for key in ("color", "scalar_opacity"):
            if key not in known:
                raise ValueError(f"transfer function lacks '{key}'")
        return cls(**known)
