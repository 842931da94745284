"""``python -m hil ARGS`` is ``emacheck ARGS``."""

from hil.cli import entry

entry()
