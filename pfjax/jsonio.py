"""Strict JSON for every file and line pfjax writes.

JSON has no NaN or infinity: Python's ``json`` writes them as bare ``NaN``/``Infinity``, which
other parsers reject. :func:`dumps` writes them as ``null`` and converts NumPy scalars and arrays
to plain numbers and lists, so every output parses anywhere.
"""

from __future__ import annotations

import json
import math
from pathlib import Path


def _default(o):
    import numpy as np

    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def clean(o):
    """``o`` with every non-finite float replaced by None and -0.0 by 0.0 (recursively through
    dicts and lists)."""
    if isinstance(o, float):
        return o + 0.0 if math.isfinite(o) else None  # -0.0 + 0.0 is 0.0
    if isinstance(o, dict):
        return {k: clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [clean(v) for v in o]
    return o


def dumps(obj, **kw) -> str:
    """Strict JSON of ``obj`` (NaN and infinities as null; NumPy values as plain ones)."""
    return json.dumps(clean(json.loads(json.dumps(obj, default=_default))), allow_nan=False, **kw)
