"""The PNG files of an evaluation, each drawn only when the data it draws have changed since the last one.

A digest of the data (arrays by their bytes, the config by its fields) is kept per PNG in FIGURE_DIGESTS.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import jax
import numpy as np

from reach_jax.evaluate import figures
from reach_jax.store import files

# {PNG name: digest of the data it draws}, so that a figure whose data has not changed is neither drawn nor written
FIGURE_DIGESTS = "figures.json"


def _canonical(x):
    """x as JSON data for a digest: an array as its dtype, shape and the SHA-256 of its bytes, a dataclass (the
    config) as its fields, a tuple (NamedTuples included) as a list."""
    if isinstance(x, np.ndarray | np.generic | jax.Array):
        a = np.ascontiguousarray(x)
        return {"dtype": a.dtype.str, "shape": a.shape, "sha256": hashlib.sha256(a.tobytes()).hexdigest()}
    if dataclasses.is_dataclass(x):
        return _canonical(dataclasses.asdict(x))
    if isinstance(x, dict):
        return {str(k): _canonical(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_canonical(v) for v in x]
    return x


def data_digest(*data) -> str:
    """SHA-256 of the data a figure draws (arrays, JSON-like values, the config), equal exactly when the data are."""
    return hashlib.sha256(json.dumps(_canonical(data), sort_keys=True).encode()).hexdigest()


class Figures:
    """Writes the PNGs of an evaluation into a folder, each drawn only when the data it draws have changed.

    FIGURE_DIGESTS in the folder keeps each PNG's data digest; a PNG whose digest matches keeps its bytes and mtime.
    """

    def __init__(self, out: Path):
        self.out, self.path = out, out / FIGURE_DIGESTS
        try:
            self.stored = json.loads(self.path.read_text())
        except (OSError, json.JSONDecodeError):
            self.stored = {}  # none yet, or unreadable: every figure is drawn
        self.digests: dict[str, str] = {}

    def draw(self, name: str, plot, *data) -> None:
        """Write plot(*data) (a matplotlib Figure) as `name`, unless the PNG there drew the same data."""
        digest = self.digests[name] = data_digest(*data)
        if self.stored.get(name) == digest and (self.out / name).is_file():
            return
        files.atomic_write_bytes(self.out / name, figures.png_bytes(plot(*data)))

    def close(self) -> None:
        """Write FIGURE_DIGESTS, if it changed."""
        if self.digests != self.stored:
            files.atomic_write_bytes(self.path, json.dumps(self.digests, indent=2, sort_keys=True).encode())
