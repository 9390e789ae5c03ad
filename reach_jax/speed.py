"""How the compiled loops run: padding, draw blocks, buffer donation, the sparse layer 1 (no units)."""

from __future__ import annotations

from dataclasses import dataclass

MAX_HIDDEN_PAD = 128  # largest Speed.hidden_pad: a TPU vector row of float32; wider only wastes memory


@dataclass(frozen=True)
class Speed:
    """How the compiled loops run. Results do not depend on it bit for bit, except for `sparse_layer1`, which
    only the lever benchmark turns off: a run stores that one (`RESULT_FIELDS`) and resumes only under it.

    `benchmarks/levers.py` measures what each one gives by switching it off.
    """

    hidden_pad: int = 8  # pad the first hidden layer to a multiple of this with inert units; 1 = off
    draw_block: int = 64  # steps whose uniforms are drawn in one call; the stream does not depend on it
    donate: bool = True  # a chunk reuses its input states' buffers for its output
    # Layer 1 and its update over the inputs that can be non-zero (about 1/3 of them), not all 125. Off, the
    # same terms are summed in another order: equal to float32 rounding, not bit for bit.
    sparse_layer1: bool = True

    def __post_init__(self):
        for name, top in (("hidden_pad", MAX_HIDDEN_PAD), ("draw_block", None)):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1 or (top is not None and value > top):
                raise ValueError(f"{name}: must be a whole number in [1, {top or 'inf'}]")


DEFAULT_SPEED = Speed()
RESULT_FIELDS = ("sparse_layer1",)  # the Speed fields that change results (float32 rounding)
