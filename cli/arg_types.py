"""Argument types shared by every command, so a flag is checked the same way everywhere
(``--seed -1`` is refused at parse time with the valid range, not deep inside numpy)."""

from __future__ import annotations

import argparse


def seed(text: str) -> int:
    """A random seed: a non-negative integer (numpy's generators take no negative seed)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid int value: {text!r}; a seed is 0, 1, 2, ...") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{value}: a seed is a non-negative integer (0, 1, 2, ...)")
    return value
