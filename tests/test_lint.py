"""Lint as a habit: ``ruff check`` of the whole tree with the house's rule set, on every test run.

The rules are pyproject.toml's ``[tool.ruff.lint]`` (pycodestyle E/W at 120 characters, pyflakes,
import order, bugbear, pyupgrade, simplify; each rule left out says why there). A finding fails the
test with ruff's own ``file:line:column: code message`` lines. Where ruff is not installed (it is in
the ``test`` extra) the test skips with that reason, and fails under ``CI=true``
(:func:`support.ci.skip_or_fail`).
"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

from support.ci import skip_or_fail

ROOT = Path(__file__).resolve().parents[1]
#: what is linted: the product, the shipped profiles' package and the tests (with support/, bench/, vcan/)
TREE = ("hil", "blf", "sim", "tests", "profiles")
#: one finding in ruff's concise output: ``path:line:column: CODE message``
FINDING = re.compile(r"^(?P<path>\S+?):(?P<line>\d+):(?P<col>\d+): (?P<code>[A-Z]+\d+)\b")


def _ruff(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    if importlib.util.find_spec("ruff") is None:
        skip_or_fail("ruff is not installed (pip install -e '.[test]')")
    return subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format", "concise",
                           *args], cwd=cwd, capture_output=True, text=True, timeout=120)


def test_the_tree_is_lint_clean():
    r = _ruff(*TREE)
    findings = [line for line in r.stdout.splitlines() if FINDING.match(line)]
    assert r.returncode == 0, (f"ruff check {' '.join(TREE)}: {len(findings)} finding(s) "
                               f"(fix the code; `ruff check --fix` does the safe ones)\n" + r.stdout + r.stderr)


def test_the_rule_set_finds_what_it_is_meant_to(tmp_path):
    """The check itself: the house's configuration flags an unused import, a zip without strict= and a
    line over 120 characters (so a config that silently selects nothing cannot pass)."""
    bad = tmp_path / "bad.py"
    bad.write_text("import os\n\n\ndef f(a, b):\n    return list(zip(a, b))\n\n\n"
                   f"X = {'1 + ' * 40}1\n")
    r = _ruff("--config", str(ROOT / "pyproject.toml"), str(bad), cwd=tmp_path)
    assert r.returncode == 1, r.stdout + r.stderr
    found = [(m["path"], m["code"]) for m in map(FINDING.match, r.stdout.splitlines()) if m]
    assert sorted(found) == [("bad.py", "B905"), ("bad.py", "E501"), ("bad.py", "F401")], r.stdout
