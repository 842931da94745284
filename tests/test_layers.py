"""The house's import rules and size limit, checked on the source (an AST walk of every module).

* ``blf`` (pure analysis) imports nothing from ``hil`` or ``sim``;
* ``sim`` (physics and simulated drives) imports from ``hil`` only ``hil.canopen``;
* ``hil.canopen`` (the CANopen vocabulary both ends speak) imports nothing from the
  rest of ``hil``, nor from ``sim`` or ``blf``;
* no module of the product is longer than 700 lines.

Imports inside functions count as much as those at the top of a module.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("hil", "blf", "sim")
MAX_LINES = 700


def _modules() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in the module, relative ones resolved."""
    tree = ast.parse(path.read_text(), filename=str(path))
    me = _module_name(path)
    package = me if path.name == "__init__.py" else me.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            out.append((node.lineno, mod))
            # ``from hil import canopen`` imports hil.canopen, ``from sim import effects`` sim.effects
            out += [(node.lineno, f"{mod}.{a.name}") for a in node.names]
    return out


def _violation(importer: str, imported: str) -> str | None:
    top = imported.split(".")[0]
    inside = lambda pkg: imported == pkg or imported.startswith(pkg + ".")  # noqa: E731
    if importer.startswith("blf") and top in ("hil", "sim"):
        return "blf imports nothing from hil or sim"
    if importer.startswith("sim") and top == "hil" and not inside("hil.canopen") and imported != "hil":
        return "sim imports from hil only hil.canopen"
    if importer.startswith("hil.canopen") and (top in ("sim", "blf") or (top == "hil" and not inside("hil.canopen")
                                                                       and imported != "hil")):
        return "hil.canopen imports nothing from the rest of hil, nor from sim or blf"
    return None


def test_the_walk_sees_every_kind_of_import(tmp_path):
    """The checker itself: top-level, function-level, relative and ``from pkg import module`` imports."""
    pkg = tmp_path / "blf"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    mod = pkg / "x.py"
    mod.write_text("import numpy\nfrom . import y\ndef f():\n    from hil.runfolder import read_signals\n"
                   "    import sim.plant\nfrom hil import canopen\n")
    names = [m for _, m in _imports_at(mod, tmp_path)]
    assert "hil.runfolder" in names and "sim.plant" in names and "blf.y" in names and "hil.canopen" in names
    assert _violation("blf.x", "hil.runfolder") and _violation("blf.x", "sim.plant")
    assert _violation("sim.plant", "hil.master") and not _violation("sim.plant", "hil.canopen.frame")
    assert _violation("hil.canopen.pdo", "hil.errors") and _violation("hil.canopen.pdo", "blf.errors")
    assert not _violation("hil.canopen.pdo", "hil.canopen.frame") and not _violation("hil.master", "sim.plant")


def _imports_at(path: Path, root: Path) -> list[tuple[int, str]]:
    global ROOT
    saved, ROOT = ROOT, root
    try:
        return _imports(path)
    finally:
        ROOT = saved


def test_import_rules():
    bad = []
    for path in _modules():
        me = _module_name(path)
        for line, imported in _imports(path):
            why = _violation(me, imported)
            if why:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {imported} ({why})")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_over_700_lines(path):
    n = len(path.read_text().splitlines())
    assert n <= MAX_LINES, f"{path.relative_to(ROOT)} has {n} lines (at most {MAX_LINES})"
