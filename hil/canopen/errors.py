"""Errors of the CANopen vocabulary (:mod:`hil.canopen`).

The root is :class:`CanopenError`; each error mixes in the builtin that
describes its nature, so a caller may catch either. The protocol errors that
carry data of their own live next to their protocol: :class:`~hil.canopen.frame.FrameError`,
:class:`~hil.canopen.pdo.PdoError`, :class:`~hil.canopen.sdo.SdoAbortError`,
:class:`~hil.canopen.sdo.SdoTimeout`, :class:`~hil.canopen.cia402.IllegalTransition`.

This package imports nothing from the rest of emacheck (see ``tests/test_layers.py``).
"""

from __future__ import annotations


class CanopenError(Exception):
    """Base of every error raised by :mod:`hil.canopen` (and by the simulated drives of sim/drives)."""


class CanopenInputError(CanopenError, ValueError):
    """A bad argument to a protocol function: the message names it, its value and its unit or range.

    (The pure analysis' and physics' counterpart is :class:`blf.errors.InputError`.)"""


class EdsError(CanopenError, ValueError):
    """An EDS/DCF file or object dictionary that cannot be used; the message names the file or object."""
