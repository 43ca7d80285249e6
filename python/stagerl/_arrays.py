"""Argument checks shared by the numpy-facing modules."""

from __future__ import annotations

from typing import Optional

import numpy as np


def rows(name: str, a, cols: Optional[int]) -> np.ndarray:
    """``a`` as a C-contiguous float64 array of shape (N, cols) (a 1-D array is one row); a
    ValueError naming ``name``, the shape and the expected shape otherwise. ``cols=None``: any
    number of columns."""
    try:
        arr = np.ascontiguousarray(a, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"`{name}` is invalid: an array of numbers ({e})") from None
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or (cols is not None and arr.shape[1] != cols):
        want = f"(N, {cols}) or ({cols},)" if cols else "(N, J) or (J,)"
        raise ValueError(f"`{name}.shape` = {np.shape(a)} is invalid: expected {want}")
    return arr
