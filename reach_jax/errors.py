"""Errors for the user: messages that always print on one line."""

from __future__ import annotations


def printable(text: str) -> str:
    """Text with unprintable characters (newlines, controls) escaped, so an error message stays on one line.

    Printable text, escapes included, passes unchanged, so applying it twice is harmless.
    """
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode() for c in text)


class OneLineError(ValueError):
    """An error for the user whose message always prints on one line."""

    def __str__(self) -> str:
        return printable(super().__str__())
