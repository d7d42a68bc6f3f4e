"""Strict JSON: the one sanitiser for values that may hold non-finite floats or numpy types.

``json.dumps`` writes ``NaN``/``Infinity`` (not JSON) for non-finite floats and rejects numpy
scalars and arrays. :func:`json_safe` turns such a value into plain Python that
``json.dumps(..., allow_nan=False)`` accepts: non-finite floats become the strings ``"nan"``,
``"inf"`` and ``"-inf"`` (or ``None`` with ``non_finite=None``), numpy scalars their Python
value, arrays lists, tuples lists and keys strings; a string that cannot be UTF-8 (a lone
surrogate) gets its bad characters as backslash escapes. Anything else (e.g. a ``datetime`` for
FastAPI's encoder) is returned unchanged for the caller's encoder to handle.

Used by frame metadata (:mod:`sim_core.frame_io`), comparison reports (:mod:`sim_core.metrics`)
and the service's database columns and responses.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

#: sentinel: non-finite floats become the strings "nan", "inf", "-inf"
AS_STRING = "string"


def json_safe(obj: Any, non_finite: str | None = AS_STRING) -> Any:
    """``obj`` as strict-JSON-ready Python (see the module docstring).

    ``non_finite``: ``"string"`` (the default) writes NaN and +-inf as ``"nan"``, ``"inf"``,
    ``"-inf"``; ``None`` writes them as ``null``.
    """
    if isinstance(obj, dict):
        return {str(k): json_safe(v, non_finite) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v, non_finite) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist(), non_finite)
    if isinstance(obj, bool | np.bool_):
        return bool(obj)
    if obj is None:
        return obj
    if isinstance(obj, str):
        try:
            obj.encode("utf-8")
        except UnicodeEncodeError:  # a lone surrogate (e.g. "\ud800" in a request) is no UTF-8
            return obj.encode("utf-8", "backslashreplace").decode("utf-8")
        return obj
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        v = float(obj)
        if math.isfinite(v):
            return v
        if non_finite is None:
            return None
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf")
    return obj


def dumps_strict(obj: Any, **kwargs: Any) -> str:
    """``json.dumps(json_safe(obj), allow_nan=False, **kwargs)``."""
    return json.dumps(json_safe(obj), allow_nan=False, **kwargs)
