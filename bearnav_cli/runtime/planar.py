"""Plane vectors over the last axis of numpy arrays: the small helpers of the runtime's geometry.

Numpy only; every function broadcasts and works on any leading shape.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["cross", "dot", "norm", "points", "safe"]


def points(x: Any) -> np.ndarray:
    """``x`` as float points, shape (R, 2)."""
    return np.asarray(x, float).reshape(-1, 2)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a₁b₂ − a₂b₁`` over the last axis (broadcasting)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a₁b₁ + a₂b₂`` over the last axis (broadcasting)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def norm(v: np.ndarray) -> np.ndarray:
    """``‖v‖`` over the last axis (``hypot``)."""
    return np.hypot(v[..., 0], v[..., 1])


def safe(den: np.ndarray) -> np.ndarray:
    """``den`` with its zeros replaced by 1, so a division never produces inf or NaN."""
    return np.where(den != 0, den, 1.0)
