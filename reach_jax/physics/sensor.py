"""The 5x5 area-ratio visual sensor (section 4.2, model §2).

Units: positions [m] in the shoulder frame; cell outputs are area fractions in [0, 1].
Cells are indexed row-major, row 0 at the lowest y and column 0 at the lowest x.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from reach_jax.config import SensorConfig


def field_bounds(cfg: SensorConfig) -> tuple[tuple[float, float], tuple[float, float]]:
    """((x_min, y_min), (x_max, y_max)) of the visual field [m]."""
    half = 0.5 * cfg.n_cells * cfg.cell_size
    cx, cy = cfg.centre
    return (cx - half, cy - half), (cx + half, cy + half)


def cell_edges(cfg: SensorConfig) -> tuple[jax.Array, jax.Array]:
    """Lower edges (n,) [m] of the cell columns (x) and rows (y)."""
    (x0, y0), _ = field_bounds(cfg)
    k = jnp.arange(cfg.n_cells) * cfg.cell_size
    return x0 + k, y0 + k


def _overlap(lo_a, hi_a, lo_b, hi_b):
    return jnp.maximum(0.0, jnp.minimum(hi_a, hi_b) - jnp.maximum(lo_a, lo_b))


def render(hand: jax.Array, target: jax.Array, cfg: SensorConfig) -> jax.Array:
    """Fraction of each cell covered by the union of the hand and target squares.

    Args:
      hand: (2,) hand centre [m].
      target: (2,) target centre [m].
      cfg: sensor geometry; both squares have side cfg.cell_size.

    Returns:
      (n_cells**2,) cell outputs in [0, 1], row-major from the lowest y.
    """
    half = 0.5 * cfg.cell_size
    xe, ye = cell_edges(cfg)
    cell_lo = (xe, ye)
    cell_hi = (xe + cfg.cell_size, ye + cfg.cell_size)
    both_lo = jnp.maximum(hand, target) - half
    both_hi = jnp.minimum(hand, target) + half

    def covered(lo, hi):
        # Per-axis overlap with every cell; the 2-D area is their outer product.
        ox = _overlap(cell_lo[0], cell_hi[0], lo[0], hi[0])
        oy = _overlap(cell_lo[1], cell_hi[1], lo[1], hi[1])
        return jnp.outer(oy, ox)

    area = covered(hand - half, hand + half) + covered(target - half, target + half) - covered(both_lo, both_hi)
    return (area / cfg.cell_size**2).reshape(-1)
