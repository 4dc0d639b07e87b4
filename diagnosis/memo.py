"""The last few results of a costly pure function of arrays, keyed by the arrays' bytes.

A fit evaluates each effect many times at the same parameters: a difference Jacobian moves one
other effect's parameter at a time, and the tare's variable projection (diagnosis/separable.py)
re-evaluates the residual with only the tare changed. An effect whose torque costs a pass over
every sample of every window (the sigmoid friction, the encoders' inverse dynamics) keeps its
last few results instead of recomputing them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Generic, TypeVar

import numpy as np

T = TypeVar("T")

SIZE = 8
"""Results kept: the current point and the few a Jacobian or a line search comes back to."""


class Memo(Generic[T]):
    """``memo(compute, *arrays)``: ``compute()``'s result for these arrays, computed once while
    it stays among the last :data:`SIZE` asked."""

    def __init__(self, size: int = SIZE) -> None:
        self._size = size
        self._kept: dict[tuple[bytes, ...], T] = {}

    def __call__(self, compute: Callable[[], T], *key: np.ndarray | str) -> T:
        k = tuple(x.encode() if isinstance(x, str) else np.ascontiguousarray(x).tobytes()
                  for x in key)
        hit = self._kept.get(k)
        if hit is None:
            hit = compute()
            if len(self._kept) >= self._size:
                self._kept.pop(next(iter(self._kept)))
            self._kept[k] = hit
        return hit
