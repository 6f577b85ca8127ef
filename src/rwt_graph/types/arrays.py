"""Checks of numeric arrays that arrive as numpy arrays (CBOR typed arrays, D21, D27).

A CBOR typed array (RFC 8746) reaches the graph as a read-only 1-D numpy array
(``rwt_protocol.codecs.cbor``). Such an array is checked as a whole, by its
element type and, when that type is wider than the field's, by its minimum
and maximum, and stays a numpy array in the internal form, so a large map or
point cloud never becomes a Python list (B9). Arrays whose
element kind does not fit the field (floats for an int field, ints for a
bool field...) return None here; the caller checks them as lists, which
gives the usual per-element error texts (D9).

numpy is looked up, not imported: an array can only exist once numpy is
loaded, and a server that never sees one never loads it.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

from .problem import FLOAT32_MAX, Problem

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

__all__ = ["int_array", "is_ndarray", "octet_bytes", "real_array"]


def is_ndarray(value: object) -> bool:
    """Whether ``value`` is a numpy array (False when numpy was never imported)."""
    numpy = sys.modules.get("numpy")
    return numpy is not None and isinstance(value, numpy.ndarray)


def int_array(
    value: npt.NDArray[np.generic], base: str, low: int, high: int
) -> npt.NDArray[np.generic] | None:
    """``value`` as an array of the integer field type ``base``, or None (check it as a list).

    Args:
        value: a 1-D numpy array.
        base: the ROS integer type whose numpy type has the same name
            (``int8`` ... ``uint64``); others (``char``, ``byte``) return None.
        low: the smallest value allowed.
        high: the largest value allowed.

    Raises:
        Problem: an element is out of ``[low, high]``; the suffix names it.
    """
    import numpy as np  # noqa: PLC0415 - loaded already: ``value`` is an array

    if value.dtype.kind not in "iu" or not hasattr(np, base):
        return None
    target = np.dtype(base)
    wider = not np.can_cast(value.dtype, target, casting="safe")
    # min and max as Python ints: no overflow whatever the two types' ranges.
    if wider and value.size and (int(value.min()) < low or int(value.max()) > high):
        for index, item in enumerate(value.tolist()):  # only to name the first offender
            if not low <= item <= high:
                raise Problem(f"expected {base} in [{low}, {high}], got {item}", f"[{index}]")
    return value if value.dtype == target else value.astype(target)


def real_array(value: npt.NDArray[np.generic], base: str) -> npt.NDArray[np.generic] | None:
    """``value`` as the array of a float field (``float32``/``float64``), or None.

    Floats keep their precision (a float64 array sent for a float32 field stays
    float64, as a JSON list of floats does); integer arrays become float64.

    Raises:
        Problem: a finite element is beyond the float32 range (REF §4.2).
    """
    import numpy as np  # noqa: PLC0415 - loaded already: ``value`` is an array

    kind = value.dtype.kind
    if kind in "iu":
        return value.astype(np.float64)
    if kind != "f":
        return None
    if base == "float32" and value.dtype.itemsize > 4 and value.size:
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(np.isfinite(value) & (np.abs(value) > FLOAT32_MAX))
        if bad.size:
            index = int(bad[0])
            raise Problem(
                f"expected float32 in [{-FLOAT32_MAX!r}, {FLOAT32_MAX!r}], "
                f"got {float(value[index])!r}",
                f"[{index}]",
            )
    return value


def octet_bytes(value: npt.NDArray[np.generic]) -> bytes | None:
    """The bytes of a ``uint8`` array (for ``uint8[]``/``char[]`` fields), or None."""
    return value.tobytes() if value.dtype.kind == "u" and value.dtype.itemsize == 1 else None
