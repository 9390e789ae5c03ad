"""Errors for the user: one-line messages, the command lines' parser and argument types that raise them, and the
exit codes they map to (docs/reliability.md lists every guarantee with its code)."""

from __future__ import annotations

import argparse
import math

EXIT_USAGE = 2  # bad arguments, config or checkpoint, or a run dir that another live process trains; nothing written
EXIT_NUMERICS = 3  # a learner went non-finite; the last good checkpoint is kept
EXIT_IO = 4  # a write failed; the last good checkpoint (or the run) is kept
EXIT_PEER = 5  # another process of a multi-process run stopped; the last good checkpoint is kept
EXIT_INTERRUPTED = 6  # stopped by SIGTERM or SIGINT after checkpointing the chunk in flight; resume as it says


def printable(text: str) -> str:
    """Text with unprintable characters (newlines, controls) escaped, so an error message stays on one line.

    Printable text, escapes included, passes unchanged, so applying it twice is harmless.
    """
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in text)


class OneLineError(ValueError):
    """An error for the user whose message always prints on one line."""

    def __str__(self) -> str:
        return printable(super().__str__())


class UsageError(OneLineError):
    """Bad command-line input; the message is one line."""


def error_line(prog: str, message: str) -> str:
    """The one line a command prints for a user error: "prog: error: message", control characters escaped."""
    return f"{prog}: error: {printable(message)}\n"


class Parser(argparse.ArgumentParser):
    """An ArgumentParser that raises UsageError instead of printing and exiting."""

    def error(self, message):
        raise UsageError(message)


def whole_number(text: str, minimum: int, maximum: int = 2**31 - 1) -> int:
    """`text` as an int in [minimum, maximum]; raises argparse.ArgumentTypeError (2e6 is a whole number too)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value < minimum or value != int(value) or value > maximum:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number in [{minimum}, {maximum}]")
    return int(value)


def positive_int(text: str) -> int:
    """An argparse type: a whole number of at least 1."""
    return whole_number(text, 1)


def non_negative_int(text: str) -> int:
    """An argparse type: a whole number of at least 0."""
    return whole_number(text, 0)
