"""Plane-vector helpers shared by the compiled training step (JAX) and the evaluation (NumPy); lengths [m]."""

from __future__ import annotations

import numpy as np


def perpendicular(aim, rel):
    """Signed component of `rel` across the unit vector `aim`, + to the left of it (the 2-D cross product).

    Only indexing and arithmetic, so the same float operations run on NumPy arrays and on JAX arrays in jit.

    Args:
      aim: (..., 2) unit vectors.
      rel: (..., 2) vectors [m], broadcast against `aim`.
    """
    return aim[..., 0] * rel[..., 1] - aim[..., 1] * rel[..., 0]


def unit(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis of a NumPy array; NaN where a vector is zero."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 0, v / np.where(n > 0, n, 1.0), np.nan)
