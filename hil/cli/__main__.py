"""``python -m hil.cli ARGS`` is ``emacheck ARGS`` (the one entry point, :func:`hil.cli.entry`)."""

from hil.cli import entry

entry()
