"""The 5x5 area-ratio visual sensor (section 4.2, model §2): where it sits, as data, and what it sees.

Units: positions [m] in the shoulder frame; cell outputs are area fractions in [0, 1].
Cells are indexed row-major, row 0 at the lowest y and column 0 at the lowest x.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from reach_jax.config import SensorConfig


@struct.dataclass
class Placement:
    """Where a learner's visual field sits and the side of its cells: per-learner data (model §2).

    Each value is rounded once from float64 (`placement`), as a constant of the config would be, and the area is
    divided by as a multiplication with its float32 reciprocal, which is what XLA made of the division by a constant:
    a learner of the config's own sensor computes the same bits as when the sensor was a constant.
    """

    lo: jax.Array  # (2,) lower-left corner of the field [m]
    hi: jax.Array  # (2,) upper-right corner of the field [m]
    cell: jax.Array  # () cell side, also the side of the hand and target squares [m]
    inv_cell_area: jax.Array  # () 1 / cell area [1/m^2], rounded from the float32 area


def placement(cfg: SensorConfig) -> Placement:
    """The sensor of `cfg` as data."""
    lo, hi, cell, area = (jnp.asarray(v, dtype=float) for v in (*field_bounds(cfg), cfg.cell_size, cfg.cell_size**2))
    return Placement(lo=lo, hi=hi, cell=cell, inv_cell_area=1.0 / area)


def field_bounds(cfg: SensorConfig) -> tuple[tuple[float, float], tuple[float, float]]:
    """((x_min, y_min), (x_max, y_max)) of the visual field [m]."""
    half = 0.5 * cfg.n_cells * cfg.cell_size
    cx, cy = cfg.centre
    return (cx - half, cy - half), (cx + half, cy + half)


def cell_edges(where: Placement, n_cells: int) -> tuple[jax.Array, jax.Array]:
    """Lower and upper edges (2, n_cells) [m] of the cell columns (x, row 0) and rows (y, row 1).

    An upper edge is the cell's offset plus (corner + cell), summed in that order: XLA folded the two constants of a
    sensor that was a constant into one, and the data keeps its bits.
    """
    k = jnp.arange(n_cells) * where.cell
    return k + where.lo[:, None], k + (where.lo + where.cell)[:, None]


def _overlap(lo_a, hi_a, lo_b, hi_b):
    return jnp.maximum(0.0, jnp.minimum(hi_a, hi_b) - jnp.maximum(lo_a, lo_b))


def render(hand: jax.Array, target: jax.Array, where: Placement, n_cells: int) -> jax.Array:
    """Fraction of each cell covered by the union of the hand and target squares.

    Args:
      hand: (2,) hand centre [m].
      target: (2,) target centre [m].
      where: the visual field; both squares have the side of its cells.
      n_cells: cells per side.

    Returns:
      (n_cells**2,) cell outputs in [0, 1], row-major from the lowest y.
    """
    half = 0.5 * where.cell
    cell_lo, cell_hi = cell_edges(where, n_cells)
    both_lo = jnp.maximum(hand, target) - half
    both_hi = jnp.minimum(hand, target) + half

    def covered(lo, hi):
        # Per-axis overlap with every cell; the 2-D area is their outer product.
        ox = _overlap(cell_lo[0], cell_hi[0], lo[0], hi[0])
        oy = _overlap(cell_lo[1], cell_hi[1], lo[1], hi[1])
        return jnp.outer(oy, ox)

    area = covered(hand - half, hand + half) + covered(target - half, target + half) - covered(both_lo, both_hi)
    return (area * where.inv_cell_area).reshape(-1)
