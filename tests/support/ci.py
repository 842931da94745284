"""Skip on a developer's laptop, fail in CI: the one rule for a test stage that cannot run here.

A stage CI is meant to run (the vcan stage, the PostgreSQL history tests, eds-utils' validation, the
recordings of ../shared, the two-process SIGKILL of ``run``) skips with its reason where it cannot run:
on a laptop that is information. Under ``CI=true`` (what CI services set; also ``1``/``yes``) the same
test fails with that reason instead: a CI run that skipped what it exists to run would pass without
having checked it. ``.ci/run`` installs what these stages need.
"""

from __future__ import annotations

import os
from typing import NoReturn

import pytest

#: values of $CI that mean "this is a CI run"
_TRUE = {"1", "true", "yes"}


def in_ci() -> bool:
    """True when the environment says this is a CI run (``CI=true``, ``1`` or ``yes``, any case)."""
    return os.environ.get("CI", "").strip().lower() in _TRUE


def skip_or_fail(reason: str) -> NoReturn:
    """Skip the test with ``reason``; under CI=true fail it with the same reason."""
    if in_ci():
        pytest.fail(f"CI=true: this stage must run in CI but cannot run here: {reason}", pytrace=False)
    pytest.skip(reason)
