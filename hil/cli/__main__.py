"""``python -m hil.cli ARGS`` is ``emacheck ARGS``."""

import sys

from hil.cli import main

sys.exit(main())
