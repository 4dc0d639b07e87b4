"""Strict JSON for everything serpar prints or writes about a run: no NaN or Infinity (which
RFC 8259 has no words for and strict parsers reject), ``null`` in their place.

A float that is not finite becomes ``None``; numpy scalars and arrays become Python numbers and
lists; anything else JSON has no type for becomes its ``float`` if it has one, else its ``str``.
"""

from __future__ import annotations

import json
import math
from typing import Any


def finite(obj: Any) -> Any:
    """`obj` with every non-finite float replaced by None, ready for ``allow_nan=False``."""
    if obj is None or isinstance(obj, (bool, int, str)):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    if hasattr(obj, "tolist"):  # numpy scalars and arrays
        return finite(obj.tolist())
    try:
        return finite(float(obj))
    except (TypeError, ValueError):
        return str(obj)


def dumps(obj: Any, indent: int | None = None) -> str:
    """Strict JSON text of `obj` (non-finite floats as null)."""
    return json.dumps(finite(obj), indent=indent, allow_nan=False)
