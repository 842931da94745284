"""Typed exception tree of emacheck.

Every error the tool raises on purpose derives from :class:`EmacheckError` and
mixes in the builtin that describes its nature, so callers can catch either.
"""

from __future__ import annotations


class EmacheckError(Exception):
    """Base of all emacheck errors."""


class ProfileError(EmacheckError, ValueError):
    """A profile (TOML) is malformed, incomplete or outside the hard limits."""


class RecordingError(EmacheckError, ValueError):
    """A recording (signals CSV, run folder, CAN log) cannot be used."""


class IncompleteRecordingError(RecordingError):
    """A recording that is well-formed but ends too early or holds no data (e.g. a killed run)."""


class AnalysisError(EmacheckError, ValueError):
    """The data do not support the requested analysis (e.g. no backlash traversal)."""


class SequenceError(EmacheckError, RuntimeError):
    """The check sequence reached a state it cannot continue from."""


class InputError(EmacheckError, ValueError):
    """Bad arrays or arguments passed to a pure function of blf/ or sim/.

    The message quotes the offending argument, its shape and its unit.
    """
