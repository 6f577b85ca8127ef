"""What a primitive checker raises, and the float32 limit the checkers share."""

from __future__ import annotations

__all__ = ["FLOAT32_MAX", "Problem"]

#: Largest finite float32, as a float64 (REF §4.2 "Float range").
FLOAT32_MAX = 3.4028234663852886e38


class Problem(Exception):
    """A value does not fit its type; converted to a ``FieldError`` by the caller.

    Args:
        problem: the text, ``expected int32, got str``.
        suffix: path below the field that holds the bad value, ``[3]`` or ``.sec``.
    """

    def __init__(self, problem: str, suffix: str = "") -> None:
        super().__init__(problem)
        self.problem = problem
        self.suffix = suffix
