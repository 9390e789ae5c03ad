"""One per-learner hyperparameter's schema: its default, range, command-line reading and words (model §5, §11)."""

from __future__ import annotations

import math
from dataclasses import dataclass

SWITCH_WORDS = {"false": 0.0, "true": 1.0}  # a switch's words on the command line, beside 0 and 1


@dataclass(frozen=True)
class Hyperparameter:
    """One per-learner learning constant."""

    name: str  # field of LearnerConfig and Hyper; its grid is TrainConfig.<name>_grid
    default: float  # the value of a run that does not set it
    help: str  # what it is, with the paper's equation or the documented choice (model §n)
    low: float = 0.0  # smallest allowed value
    low_open: bool = False  # True: the value must exceed `low`
    high: float = math.inf  # largest allowed value
    high_open: bool = False  # True: the value must stay below `high`
    integer: bool = False  # a count: stored as a whole number in the config
    switch: bool = False  # on/off: 0 or 1 (true or false on the command line), 1 = on; stored as a float
    neutral: float | None = None  # the value that switches an optional form off; a recipe label names it only
    # when another value is set. None: always named.
    words: str = ""  # how a recipe's description names it, `{v}` its value (`describe`)
    part_of: str | None = None  # the hyperparameter whose form this one shapes: described only while that one is on

    @property
    def grid(self) -> str:
        """The TrainConfig field that sweeps it."""
        return f"{self.name}_grid"

    @property
    def bounds(self) -> str:
        """Its allowed values in words, as --list-hyper shows them."""
        if self.switch:
            return "true/false"
        left, right = "(" if self.low_open else "[", ")" if self.high_open or self.high == math.inf else "]"
        whole = "whole, " if self.integer else ""
        return f"{whole}{left}{self.low:g}, {self.high:g}{right}"

    def parse(self, text: str) -> float:
        """A command-line value of it (a number; true/false too for a switch); raises ValueError saying why not."""
        word = text.strip().lower()
        if self.switch and word in SWITCH_WORDS:
            return SWITCH_WORDS[word]
        try:
            value = float(word)
        except ValueError:
            kind = "true, false, 0 or 1" if self.switch else "a number"
            raise ValueError(f"{self.name}={text!r} is not {kind}") from None
        why = self.check(value)
        if why:
            raise ValueError(f"{self.name}={text!r}: {why}")
        return int(value) if self.integer else value

    def check(self, value: float) -> str | None:
        """Why `value` is out of range, or None when it is allowed."""
        if self.switch:
            return None if value in (0.0, 1.0) else "must be 0 or 1 (a switch: false or true)"
        too_low = value <= self.low if self.low_open else value < self.low
        too_high = value >= self.high if self.high_open else value > self.high
        if self.integer and math.isfinite(value) and value != int(value):
            return "must be a whole number"
        if math.isfinite(value) and not too_low and not too_high:
            return None
        if self.high == math.inf:
            return "must be positive" if self.low_open and self.low == 0 else "must not be negative"
        left, right = "(" if self.low_open else "[", ")" if self.high_open else "]"
        return f"must lie in {left}{self.low:g}, {self.high:g}{right}"
