"""argtypes.py - argparse value types shared by the command lines (a bad value is a usage error, exit 2)."""
from __future__ import annotations

import argparse

__all__ = ["positive_int"]


def positive_int(text: str, hint: str = "") -> int:
    """An integer >= 1; ``hint`` is added to the message when the integer is below 1."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {v}" + (f" ({hint})" if hint else ""))
    return v
