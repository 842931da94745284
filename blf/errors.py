"""Errors of the pure analysis (and of the physics in sim/, which uses the same validators).

Each mixes in the builtin that describes its nature, so a caller may catch
either: ``except ValueError`` catches both.
"""

from __future__ import annotations


class BlfError(Exception):
    """Base of the errors raised by :mod:`blf` (and by the pure physics of :mod:`sim`)."""


class InputError(BlfError, ValueError):
    """Bad arrays or arguments passed to a pure function of blf/ or sim/.

    The message quotes the offending argument, its shape and its unit.
    """


class AnalysisError(BlfError, ValueError):
    """The data do not support the requested analysis (e.g. no backlash traversal)."""
