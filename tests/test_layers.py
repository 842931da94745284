"""The house's import rules and size limit, checked on the source (an AST walk of every module).

* ``blf`` (pure analysis) imports nothing from ``hil`` or ``sim``;
* ``sim`` (physics and simulated drives) imports from ``hil`` only ``hil.canopen``;
* ``hil.canopen`` (the CANopen vocabulary both ends speak) imports nothing from the
  rest of ``hil``, nor from ``sim`` or ``blf``;
* the sans-IO cores (``SANS_IO``: the master core, its preflight, events and drive-limit set-up; the
  check sequence, the supervisor, the freshness limit) import no IO module (a bus, a thread, a clock,
  a file, a process) and of ``hil`` only the vocabulary, the errors, the profiles' dataclasses and
  one another;
* the house's floors (:data:`FLOORS`): a room of ``hil`` (a sub-package or a top module), ``sim`` and ``blf``
  imports only rooms on lower floors, never a room above it nor a sibling beside it (no import runs back up);
* blf's wings (:data:`BLF_WINGS`): diagnose may use maint and serv, maint serv, serv neither; blf's top
  modules (errors, validate, signals, continuity, wear) use no wing;
* no two modules import each other, directly or round a circle;
* no command module of ``hil.cli`` imports another command (they share the shared modules);
* no module of the product is longer than 700 lines; none of ``blf`` and ``hil/analysis`` longer than 600, none
  of ``hil/cli`` longer than 300;
* no function or method of the product is longer than 100 lines, counted as the source lines of
  its body without its docstring: from the first statement after the docstring to the function's
  last line, blank and comment lines inside included (the signature, decorators and docstring are
  not counted; a nested function counts in its parent and on its own);
* no module uses another module's underscore names: no ``from m import _x`` of the product, and
  an attribute ``_x`` (``self._x``, ``obj._x``) only where the module itself defines ``_x``
  (a ``def``, a class, an assignment to it or to ``self._x``). Parts of one object in several
  modules (the simulated drive's mixins) share documented public hooks instead.

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


_TREES: dict[str, ast.Module] = {}


def _parse(source: str, filename: str = "<unknown>") -> ast.Module:
    """``ast.parse`` of ``source``, once per text: the import, length and private-name rules walk the same
    modules' trees (the trees are only read)."""
    tree = _TREES.get(source)
    if tree is None:
        tree = _TREES[source] = ast.parse(source, filename=filename)
    return tree


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in the module, relative ones resolved."""
    tree = _parse(path.read_text(), str(path))
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


#: The sans-IO cores: fed frames, samples and a time value; they return frames, setpoints and events.
SANS_IO = ("hil.master.core", "hil.master.preflight", "hil.master.events", "hil.master.limits_setup",
           "hil.master.stalls", "hil.master.powerup", "hil.master.views", "hil.master.drill", "hil.master.commission",
           "hil.master.commission_rules", "hil.master.jog", "hil.master.jog_rules", "hil.master.hypotheses",
           "hil.check.sequence", "hil.check.supervisor", "hil.check.staleness", "hil.check.profileclock")
#: What a sans-IO core may import of hil: the vocabulary, the errors, the profiles' dataclasses, one another.
SANS_IO_MAY = ("hil.canopen", "hil.errors", "hil.profile.config", *SANS_IO)
#: Modules that touch a bus, a thread, a clock, a file or a process.
IO_MODULES = ("can", "threading", "time", "os", "io", "pathlib", "socket", "select", "queue", "subprocess",
              "asyncio", "signal", "shutil", "tempfile", "sqlite3")


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
    if importer in SANS_IO:
        if top in IO_MODULES:
            return f"a sans-IO core imports no IO module ({top})"
        if top in ("sim", "blf") or (top == "hil" and imported not in ("hil", "hil.master", "hil.check", "hil.profile")
                                     and not any(inside(m) for m in SANS_IO_MAY)):
            return "a sans-IO core imports of hil only " + ", ".join(SANS_IO_MAY[:3]) + " and the other cores"
    return None


def test_the_walk_sees_every_kind_of_import(tmp_path):
    """The checker itself: top-level, function-level, relative and ``from pkg import module`` imports."""
    pkg = tmp_path / "blf"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    mod = pkg / "x.py"
    mod.write_text("import numpy\nfrom . import y\ndef f():\n    from hil.record.runfolder import read_signals\n"
                   "    import sim.plant\nfrom hil import canopen\n")
    names = [m for _, m in _imports_at(mod, tmp_path)]
    assert "hil.record.runfolder" in names and "sim.plant" in names and "blf.y" in names and "hil.canopen" in names
    assert _violation("blf.x", "hil.record.runfolder") and _violation("blf.x", "sim.plant")
    assert _violation("sim.plant", "hil.master.core") and not _violation("sim.plant", "hil.canopen.frame")
    assert _violation("hil.canopen.pdo", "hil.errors") and _violation("hil.canopen.pdo", "blf.errors")
    assert not _violation("hil.canopen.pdo", "hil.canopen.frame") and not _violation("hil.master.link", "sim.plant")
    assert _violation("hil.master.core", "sim.plant") and _violation("hil.check.supervisor", "hil.record.runfolder")
    assert _violation("hil.master.preflight", "time") and _violation("hil.check.sequence", "can.interfaces")
    assert _violation("hil.master.core", "hil.transport") and _violation("hil.check.staleness", "threading")
    assert not _violation("hil.master.core", "hil.master.events") and not _violation("hil.check.supervisor",
                                                                                      "hil.check.staleness")
    assert not _violation("hil.check.sequence", "hil.profile.config")
    assert not _violation("hil.master.core", "hil.master")


def _imports_at(path: Path, root: Path) -> list[tuple[int, str]]:
    global ROOT
    saved, ROOT = ROOT, root
    try:
        return _imports(path)
    finally:
        ROOT = saved


def _broken(rule) -> list[str]:
    """Every import of the product that ``rule(importer, imported)`` gives a reason against."""
    return [f"{path.relative_to(ROOT)}:{line} imports {imported} ({why})" for path in _modules()
            for line, imported in _imports(path) if (why := rule(_module_name(path), imported))]


def test_import_rules():
    bad = _broken(_violation)
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_over_700_lines(path):
    n = len(path.read_text().splitlines())
    assert n <= MAX_LINES, f"{path.relative_to(ROOT)} has {n} lines (at most {MAX_LINES})"


def _function_lengths(source: str) -> list[tuple[int, str, int]]:
    """(line of the ``def``, name, body lines without the docstring) of every function in ``source``."""
    out = []
    for node in ast.walk(_parse(source)):
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


#: underscore names a module may use without defining them: (module, name) -> why
FOREIGN_PRIVATE_OK = {
    ("hil/transport.py", "_check_if_open"): "python-can's can.BusABC helper for its interface subclasses",
    ("hil/transport.py", "_send_periodic_internal"): "python-can's can.BusABC hook an interface overrides when "
    "it has a kernel- or hardware-timed periodic send: the one way to tell that send_periodic would be a "
    "thread in this process",
    ("hil/cli/bus.py", "_multicast"): "python-can's udp_multicast bus keeps its one socket there, with no public "
    "way to set IP_MULTICAST_ALL off on it (open_bus fails closed if it is gone)",
    ("hil/cli/bus.py", "_socket"): "the socket of python-can's udp_multicast bus (see _multicast)",
    ("hil/forks.py", "_exit"): "os._exit, the documented way for a fork to end without the parent's "
    "cleanup (atexit, buffered files)",
}


def _defined_names(tree: ast.AST) -> set[str]:
    """Names a module defines: functions, classes, assigned names and ``self.``/``cls.`` attributes,
    loop and ``with`` targets, imported names."""
    out: set[str] = set()
    for n in ast.walk(tree):
        if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(n.name)
        targets: list = []
        if isinstance(n, ast.Assign):
            targets = list(n.targets)
        elif isinstance(n, (ast.AnnAssign, ast.AugAssign, ast.For, ast.comprehension)):
            targets = [n.target]
        elif isinstance(n, ast.With):
            targets = [i.optional_vars for i in n.items if i.optional_vars is not None]
        elif isinstance(n, (ast.Import, ast.ImportFrom)):
            out |= {(a.asname or a.name).split(".")[0] for a in n.names}
        while targets:
            e = targets.pop()
            if isinstance(e, (ast.Tuple, ast.List)):
                targets += e.elts
            elif isinstance(e, ast.Starred):
                targets.append(e.value)
            elif isinstance(e, ast.Name):
                out.add(e.id)
            elif isinstance(e, ast.Attribute) and isinstance(e.value, ast.Name) and e.value.id in ("self", "cls"):
                out.add(e.attr)
    return out


def _foreign_private(source: str, where: str) -> list[str]:
    """Uses of underscore names (not dunders) that the module does not define itself."""
    tree = _parse(source)
    mine = _defined_names(tree)
    bad = []
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom) and n.module and n.module.split(".")[0] in PACKAGES:
            bad += [f"{where}:{n.lineno} imports {n.module}.{a.name}" for a in n.names
                    if a.name.startswith("_") and not a.name.startswith("__")]
        elif (isinstance(n, ast.Attribute) and n.attr.startswith("_") and not n.attr.startswith("__")
              and n.attr not in mine and (where, n.attr) not in FOREIGN_PRIVATE_OK):
            bad.append(f"{where}:{n.lineno} uses {ast.unparse(n)} (not defined in this module)")
    return bad


def test_the_private_name_check_sees_what_it_is_meant_to():
    src = ("from sim.drives.stats import _Counters\n"
           "class A:\n    def __init__(self):\n        self._mine = 1\n"
           "    def _own(self):\n        return self._mine + self._theirs + other._x + self.__class__.__name__\n"
           "    def f(self, node):\n        node._own()\n        return self._own()\n")
    assert sorted(_foreign_private(src, "m.py")) == [
        "m.py:1 imports sim.drives.stats._Counters",
        "m.py:6 uses other._x (not defined in this module)",
        "m.py:6 uses self._theirs (not defined in this module)"]


def test_no_module_uses_another_modules_underscore_names():
    bad = [b for path in _modules() for b in _foreign_private(path.read_text(), str(path.relative_to(ROOT)))]
    assert not bad, ("underscore names used outside the module that defines them (make them documented "
                     "public hooks):\n" + "\n".join(bad))


#: The house's floors, top down (docs/design.md): a room imports only rooms on lower floors. A module's room is
#: the longest name here that it is or lies in; ``hil`` itself (``__version__``) is on the ground floor.
FLOORS = (
    ("hil.__main__",),
    ("hil.cli",),
    ("hil.report",),
    ("hil.analysis", "hil.master"),
    ("hil.history", "hil.check", "hil.sim_server"),
    ("hil.record",),
    ("hil.profile", "hil.transport"),
    ("hil.errors", "sim"),
    ("blf", "hil.forks", "hil.canopen", "hil"),
)
#: blf's wings, top down: a wing uses only the wings below it and blf's top modules
BLF_WINGS = ("blf.diagnose", "blf.maint", "blf.serv")
#: line limits stricter than MAX_LINES, by folder (issue 46)
FOLDER_MAX_LINES = {"blf/": 600, "hil/analysis/": 600, "hil/cli/": 300}


def _room(module: str) -> tuple[int, str] | None:
    """(floor from the top, room) of a module of the product, None for another package's."""
    best = None
    for floor, rooms in enumerate(FLOORS):
        for room in rooms:
            if (module == room or module.startswith(room + ".")) and (best is None or len(room) > len(best[1])):
                best = (floor, room)
    return best


def _runs_up(importer: str, imported: str) -> str | None:
    """Why ``importer`` may not import ``imported`` by the floors and blf's wings, or None."""
    a, b = _room(importer), _room(imported)
    if a is None or b is None or a[1] == b[1]:
        return _across_wings(importer, imported)
    if b[0] < a[0]:
        return f"runs back up: {a[1]} (floor {len(FLOORS) - a[0]}) imports {b[1]} (floor {len(FLOORS) - b[0]})"
    if b[0] == a[0]:
        return f"runs sideways: {a[1]} imports {b[1]}, a room on its own floor"
    return _across_wings(importer, imported)


def _wing(module: str) -> int | None:
    return next((i for i, w in enumerate(BLF_WINGS) if module == w or module.startswith(w + ".")), None)


def _across_wings(importer: str, imported: str) -> str | None:
    if not (importer.startswith("blf.") and imported.startswith("blf.")):
        return None
    a, b = _wing(importer), _wing(imported)
    if b is None or a == b:
        return None
    if a is None:
        return f"blf's top module {importer} uses the wing {BLF_WINGS[b]}"
    if b < a:
        return f"blf's wing {BLF_WINGS[a]} uses {BLF_WINGS[b]}, a wing above it"
    return None


def test_the_floor_rule_sees_what_it_is_meant_to():
    """The checker itself, on the imports issue 46 removed: the analysis reaching into the command line for a
    recording's actuation, the profile into the analysis for the floors' defaults, the profile into the
    history for its URL; a sibling; blf's wings upward and its top modules into a wing."""
    assert _runs_up("hil.analysis.diagnose.load", "hil.cli.common")
    assert _runs_up("hil.profile.config", "hil.analysis.diagnose.floors")
    assert _runs_up("hil.profile.load", "hil.history.url")
    assert _runs_up("hil.analysis.maint", "hil.master.core")
    assert _runs_up("hil.record.runfolder", "hil.history.record")
    assert not _runs_up("hil.analysis.diagnose.load", "hil.record.recording")
    assert not _runs_up("hil.analysis.diagnose.dual_reference", "hil.profile.floors")
    assert not _runs_up("hil.record.runfolder", "hil.record.signals_csv") and not _runs_up("hil.cli.run", "hil")
    assert _runs_up("blf.serv.blfserv", "blf.maint.segments") and _runs_up("blf.maint.accuracy", "blf.diagnose.band")
    assert _runs_up("blf.wear", "blf.maint.verdict")
    assert not _runs_up("blf.diagnose.phases", "blf.maint.segments")
    assert not _runs_up("blf.maint.accuracy", "blf.serv.filters") and not _runs_up("blf.maint.blfmaint", "blf.errors")


def test_no_import_runs_back_up_or_sideways():
    bad = _broken(_runs_up)
    assert not bad, "\n".join(bad)


def _is_module(name: str) -> bool:
    rel = ROOT / Path(*name.split("."))
    return rel.with_suffix(".py").is_file() or (rel / "__init__.py").is_file()


def _graph() -> dict[str, set[str]]:
    """module -> the modules of the product it imports (at its top or inside a function)."""
    return {_module_name(p): {m for _, m in _imports(p) if m.split(".")[0] in PACKAGES and _is_module(m)
                              and m != _module_name(p)} for p in _modules()}


def _circle(graph: dict[str, set[str]]) -> list[str] | None:
    """A circle of imports in ``graph``, or None."""
    import graphlib
    try:
        tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as exc:
        return list(exc.args[1])
    return None


def test_the_circle_finder_sees_the_two_circles_issue_46_cut():
    assert _circle({"hil.history.record": {"hil.history.store"}, "hil.history.store": {"hil.history.schema",
                    "hil.history.record"}, "hil.history.schema": {"hil.history.record"}})
    assert _circle({"hil.record.runfolder": {"hil.record.signals_csv"},
                    "hil.record.signals_csv": {"hil.record.runfolder"}})
    assert _circle({"a": {"b"}, "b": set()}) is None


def test_no_import_circle():
    circle = _circle(_graph())
    assert circle is None, "modules that import each other: " + " -> ".join(circle or ())


def _commands() -> set[str]:
    """The command modules of hil.cli: those that register a sub-command."""
    return {_module_name(p) for p in (ROOT / "hil" / "cli").glob("*.py")
            if any(isinstance(n, ast.FunctionDef) and n.name == "register" for n in _parse(p.read_text()).body)}


def test_no_command_imports_another():
    cmds = _commands()
    assert {"hil.cli.diagnose", "hil.cli.run", "hil.cli.history"} <= cmds and "hil.cli.args" not in cmds
    bad = [f"{c} imports {m}" for c in sorted(cmds) for _, m in _imports(ROOT / Path(*c.split(".")).with_suffix(".py"))
           if m in cmds and m != c]
    assert not bad, "a command takes what it shares from the shared modules, never from another command:\n" + \
        "\n".join(bad)


def _folder_limit(rel: str) -> int:
    """The line limit of a module (path from the root, / separated)."""
    return min([MAX_LINES] + [n for folder, n in FOLDER_MAX_LINES.items() if rel.startswith(folder)])


def test_folder_limits_apply_where_they_say():
    assert _folder_limit("blf/maint/blfmaint.py") == 600 and _folder_limit("hil/analysis/diagnose/load.py") == 600
    assert _folder_limit("hil/cli/args.py") == 300 and _folder_limit("hil/record/runrecord.py") == MAX_LINES


@pytest.mark.parametrize("path", [p for p in _modules() if _folder_limit(p.relative_to(ROOT).as_posix()) < MAX_LINES],
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_no_module_over_its_folders_limit(path):
    n = len(path.read_text().splitlines())
    limit = _folder_limit(path.relative_to(ROOT).as_posix())
    assert n <= limit, f"{path.relative_to(ROOT)} has {n} lines (at most {limit} in its folder)"


#: door modules that offer only part of their module's public names (the rest is the wing's own machinery)
DOOR_PARTIAL = {"blf.diagnose.fit": "the fitting machinery: the door offers safe_predict only"}


def _door_map(wing: str) -> dict[str, list[str]]:
    """{module: [names]} of a wing's door (the ``submod_attrs`` literal of its ``lazy.attach``)."""
    tree = _parse((ROOT / Path(*wing.split(".")) / "__init__.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == "submod_attrs":
            return {f"{wing}.{k}": v for k, v in ast.literal_eval(node.value).items()}
    raise AssertionError(f"{wing}/__init__.py has no lazy door (submod_attrs)")


@pytest.mark.parametrize("wing", BLF_WINGS)
def test_each_wing_door_offers_its_modules_public_names(wing):
    """A wing's door lists exactly the public names (``__all__``) of the modules it opens (some partly, said
    why), and each name resolves through it."""
    import importlib
    door = importlib.import_module(wing)
    for module, names in _door_map(wing).items():
        public = importlib.import_module(module).__all__
        assert set(names) <= set(public), f"{wing}'s door offers {set(names) - set(public)}, not public in {module}"
        if module not in DOOR_PARTIAL:
            assert set(names) == set(public), f"{wing}'s door lacks {set(public) - set(names)} of {module}"
        for name in names:
            assert getattr(door, name) is getattr(importlib.import_module(module), name)
