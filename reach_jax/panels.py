"""The movements that Fig. 4 and 5 draw: their panels and the corner cells they run between (section 4.4).

Units: positions [m] in the shoulder frame.
"""

from __future__ import annotations

import numpy as np

from reach_jax import sensor
from reach_jax.config import Config

# Fig. 4 panels: (letter, learning condition, test condition).
FIG4_PANELS = (
    ("a", "none", "none"),
    ("b", "none", "viscous"),
    ("c", "viscous", "none"),
    ("d", "viscous", "viscous"),
    ("e", "random", "none"),
    ("f", "random", "viscous"),
)
FIG5_PANELS = ("a", "d")
CORNER_NAMES = ("lower left", "lower right", "upper left", "upper right")  # order of `corner_centres`


def corner_centres(cfg: Config) -> np.ndarray:
    """Centres of the four corner cells, in CORNER_NAMES order: (4, 2) [m]."""
    (x0, y0), (x1, y1) = sensor.field_bounds(cfg.sensor)
    half = 0.5 * cfg.sensor.cell_size
    return np.array([[x0 + half, y0 + half], [x1 - half, y0 + half], [x0 + half, y1 - half], [x1 - half, y1 - half]])


def corner_pairs(cfg: Config) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fig. 4 movements between distinct corner-cell centres.

    Returns:
      (starts (12, 2) [m], targets (12, 2) [m], start corner index (12,) into CORNER_NAMES).
    """
    c = corner_centres(cfg)
    idx = np.array([(i, j) for i in range(len(c)) for j in range(len(c)) if i != j])
    return c[idx[:, 0]], c[idx[:, 1]], idx[:, 0]
