"""Inputs that put a rule exactly on its limit, and one float step either side.

A test of a limit must land on it: ``0.206 - 0.006`` is ``0.19999999999999998`` in floats, so a test
"at B - U = 0.200" never reaches the boundary and cannot tell ``>`` from ``>=``. :func:`around` walks
an input by :func:`math.nextafter` until the quantity the rule compares is the limit exactly, and
returns the neighbours whose quantity is the next representable one below and above it (the quantity
is computed as the code under test computes it, the same float operations in the same order; the
test then asserts which side the code under test puts each on).
"""

from __future__ import annotations

import math
from collections.abc import Callable

#: nextafter steps walked at most to land on the limit (a few are normal; thousands mean a bad start)
MAX_STEPS = 4096


def land(g: Callable[[float], float], target: float, x0: float) -> float:
    """The float ``x`` nearest ``x0`` with ``g(x) == target`` exactly, for ``g`` non-decreasing in ``x``.

    Raises AssertionError when ``g`` jumps over ``target`` (no float input gives it exactly): choose
    another start or other fixed inputs."""
    x = x0
    up = g(x) < target
    for _ in range(MAX_STEPS):
        v = g(x)
        if v == target:
            return x
        if (v < target) != up:
            raise AssertionError(f"g jumps over {target!r} between {x!r} and its neighbour: no float input "
                                 "lands on the limit; choose other fixed inputs")
        x = math.nextafter(x, math.inf if up else -math.inf)
    raise AssertionError(f"no input within {MAX_STEPS} float steps of {x0!r} gives {target!r}")


def around(g: Callable[[float], float], target: float, x0: float) -> tuple[float, float, float]:
    """``(below, at, above)``: ``g(at) == target``; ``below``/``above`` the nearest inputs whose
    ``g`` is below/above ``target`` (``g`` non-decreasing). Asserts the three land as intended."""
    at = land(g, target, x0)
    below = above = at
    for _ in range(MAX_STEPS):
        below = math.nextafter(below, -math.inf)
        if g(below) < target:
            break
    for _ in range(MAX_STEPS):
        above = math.nextafter(above, math.inf)
        if g(above) > target:
            break
    assert g(below) < target == g(at) < g(above), (below, at, above)
    return below, at, above
