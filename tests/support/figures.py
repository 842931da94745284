"""Reports written without rasterising their figures, for tests that assert files, names and text.

A report's figures are built as in the product (every plotting call runs, each figure is closed), but
not laid out and drawn to PNG: ``figure_uri`` (which lays a figure out and draws it,
:func:`hil.report.shell.laid_out`) returns an empty PNG data URI. The eight figures of a
maintenance report take ~2 s to draw on an idle machine, about 90 % of ``emacheck analyze`` on a short
check, and tests of which files a command writes never look at them. The drawn figures are tested
where they are asserted (test_report_signoff.py) and in the end-to-end tests (test_dry_run.py,
test_cli.py, test_verdict.py), which draw them all.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

from hil.report import shell

EMPTY_PNG_URI = "data:image/png;base64,"


def _built_not_drawn(fig: Any, *, dpi: int = 80) -> str:
    """:func:`hil.report.shell.figure_uri` without ``savefig``: closes the figure, returns an empty PNG."""
    del dpi
    shell.pyplot().close(fig)
    return EMPTY_PNG_URI


@contextmanager
def figures_unrendered() -> Iterator[None]:
    """Within it, reports build their figures but do not draw them (see the module)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(shell, "figure_uri", _built_not_drawn)
        yield
