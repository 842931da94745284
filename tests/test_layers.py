"""The house's import rules and size limit, checked on the source (an AST walk of every module).

* ``blf`` (pure analysis) imports nothing from ``hil`` or ``sim``;
* ``sim`` (physics and simulated drives) imports from ``hil`` only ``hil.canopen``;
* ``hil.canopen`` (the CANopen vocabulary both ends speak) imports nothing from the
  rest of ``hil``, nor from ``sim`` or ``blf``;
* no module of the product is longer than 700 lines;
* no function or method of the product is longer than 100 lines, counted as the source lines of
  its body without its docstring: from the first statement after the docstring to the function's
  last line, blank and comment lines inside included (the signature, decorators and docstring are
  not counted; a nested function counts in its parent and on its own).

Imports inside functions count as much as those at the top of a module.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("hil", "blf", "sim")
MAX_LINES = 700
MAX_FUNCTION_LINES = 100


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


def _function_lengths(source: str) -> list[tuple[int, str, int]]:
    """(line of the ``def``, name, body lines without the docstring) of every function in ``source``."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        body = node.body
        if isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) \
                and isinstance(body[0].value.value, str):
            body = body[1:]
        n = node.end_lineno - body[0].lineno + 1 if body else 0
        out.append((node.lineno, node.name, n))
    return out


def test_function_length_counts_the_body_without_its_docstring():
    """The counter itself: signature, decorators and docstring are not counted; blank and comment
    lines inside the body are; a nested function counts in its parent and on its own."""
    src = ("@decorator\n"
           "def f(a,\n      b):\n"
           '    """Doc\n\n    string."""\n'
           "    x = 1\n\n    # a comment\n"
           "    def g():\n        return 2\n"
           "    return x\n"
           "def h(): return 3\n"
           'def k():\n    """Only a docstring."""\n')
    assert _function_lengths(src) == [(2, "f", 6), (13, "h", 1), (14, "k", 0), (10, "g", 1)]


def test_no_function_over_100_lines():
    bad = [f"{path.relative_to(ROOT)}:{line} {name}: {n} lines"
           for path in _modules() for line, name, n in _function_lengths(path.read_text()) if n > MAX_FUNCTION_LINES]
    assert not bad, (f"functions longer than {MAX_FUNCTION_LINES} lines (body without the docstring; split them into "
                     "named steps):\n" + "\n".join(bad))
