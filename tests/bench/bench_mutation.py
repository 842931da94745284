"""Mutation benchmark of the safety-critical modules (mutmut): do the tests fail when the code is wrong?

For each module, a scratch copy of the project gets a ``[tool.mutmut]`` section that mutates only that
module and runs only its tests (``TESTS`` below, without the slow ones), and ``mutmut run`` with one
worker process. mutmut makes every small change to the module's functions it knows (a comparison
``>`` for ``>=``, a number plus one, ``and`` for ``or``, a string changed, an argument dropped or set to
None, ...) and runs the tests that reach the mutated function against each; a mutant no test fails
"survives". Survivors that cannot change behaviour (equivalent mutants) are listed with the reason in
``tests/bench/mutation_equivalent.toml``, matched by the changed line; the score is (killed + timeout) /
(mutants - equivalent), the target >= 95 % (docs/testing.md, which has the figures). A "timeout" is a
mutant whose tests ran past mutmut's CPU-time limit (SIGXCPU; e.g. a search made endless): the test run
never ends, so it is detected, as mutmut's own score counts it; it is listed apart in the counts.
"no tests" (no test reaches the mutated function) and "suspicious" count as not killed.

    pip install -e '.[test,mutation]'
    python tests/bench/bench_mutation.py                       # supervisor, verdict, maint (~15 min)
    python tests/bench/bench_mutation.py --module blf/maint/verdict.py
    python tests/bench/bench_mutation.py --module hil/canopen/cia402.py --module hil/canopen/od.py \\
        --module sim/drives/nmt_slave.py                       # the CANopen modules (~10 min)

Writes bench_mutation.json (per module: counts, score, every survivor with its diff and,
when equivalent, why). CPU-heavy: one worker process; run it alone. Not part of the test run.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EQUIVALENT = Path(__file__).with_name("mutation_equivalent.toml")

#: module -> the tests that exercise it (pytest arguments; the slow tests are deselected with -m "not slow").
#: blf/maint/blfmaint.py leaves out the 110-record acceptance fixture and the 60-record seed spreads of
#: tests/test_blf_maint.py (20 s of every mutant's run); tests/test_boundaries_maint.py has the
#: known answers that stand in for them
TESTS: dict[str, list[str]] = {
    # test_boundaries_staleness: the freshness limit in force (kept limits, its name and reason; issue 37)
    "hil/check/supervisor.py": ["tests/test_boundaries_supervisor.py", "tests/test_boundaries_staleness.py",
                                "tests/test_faults_bad_input.py"],
    "blf/maint/verdict.py": ["tests/test_boundaries_verdict.py", "tests/test_verdict.py"],
    "blf/maint/blfmaint.py": ["tests/test_boundaries_maint.py", "tests/test_blf_maint.py",
                     "-k", "not acceptance and not sigmas_match_seed_spread and not slope_sign_corners"],
    # the CANopen modules (issue 23's rewrite): the tests that pin them by mutation (issue 26) are in these files
    "hil/canopen/cia402.py": ["tests/test_cia402.py", "tests/test_sim_slave.py", "tests/test_master.py"],
    # test_bad_recordings: load_eds' refusals of a folder and of text that is not UTF-8, and a byte-order mark read
    "hil/canopen/od.py": ["tests/test_eds.py", "tests/test_master.py", "tests/test_sim_slave.py",
                          "tests/test_bad_recordings.py"],
    "sim/drives/nmt_slave.py": ["tests/test_boundaries_nmt_slave.py", "tests/test_sim_slave.py"],
}
DEFAULT = ["hil/check/supervisor.py", "blf/maint/verdict.py", "blf/maint/blfmaint.py"]
#: statuses of mutmut's mutant runs; DETECTED: the ones the score counts as killed
KILLED, SURVIVED, TIMEOUT = "killed", "survived", "timeout"
DETECTED = (KILLED, TIMEOUT)


def project_files() -> list[str]:
    """The project's files (tracked and new, not ignored); the whole tree where git is absent."""
    try:
        out = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=ROOT, capture_output=True,
                             text=True, check=True).stdout
        return [f for f in out.splitlines() if (ROOT / f).is_file()]
    except (OSError, subprocess.CalledProcessError):
        return [str(p.relative_to(ROOT)) for p in ROOT.rglob("*") if p.is_file() and ".git" not in p.parts
                and "__pycache__" not in p.parts and "mutants" not in p.parts]


def scratch_copy(dest: Path, module: str) -> None:
    for f in project_files():
        target = dest / f
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / f, target)
    tests = TESTS[module]
    cfg = (
        "\n\n[tool.mutmut]\n"
        'source_paths = ["hil", "blf", "sim", "profiles"]\n'
        f"only_mutate = [{json.dumps(module)}]\n"
        f"pytest_add_cli_args_test_selection = {json.dumps(tests)}\n"
        # in mutmut's own process: its trampoline and test stats do not cross to pytest-xdist's workers
        'pytest_add_cli_args = ["-p", "no:cacheprovider", "-p", "no:xdist", "-m", "not slow"]\n'
    )
    with open(dest / "pyproject.toml", "a") as fh:
        fh.write(cfg)


def mutmut_env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "CI")}  # import the mutated copy
    env["MPLBACKEND"] = "Agg"
    return env


def results(work: Path) -> dict[str, str]:
    out = subprocess.run([sys.executable, "-m", "mutmut", "results", "--all", "true"], cwd=work, env=mutmut_env(),
                         capture_output=True, text=True, check=True).stdout
    return dict(re.findall(r"^\s+(\S+): (.+)$", out, flags=re.M))


def diff_of(work: Path, name: str) -> list[str]:
    out = subprocess.run([sys.executable, "-m", "mutmut", "show", name], cwd=work, env=mutmut_env(),
                         capture_output=True, text=True, check=False).stdout
    return [ln for ln in out.splitlines() if ln[:1] in "-+" and not ln.startswith(("---", "+++"))]


def load_equivalent() -> dict[str, list[dict]]:
    if not EQUIVALENT.exists():
        return {}
    return tomllib.loads(EQUIVALENT.read_text())


def matches(entry: dict, diff: list[str], name: str) -> bool:
    """An equivalent-mutant entry: the function (part of mutmut's ``x_<function>`` name) and text of the
    removed and of the added line."""
    if entry["function"] not in name:
        return False
    removed = [d[1:].strip() for d in diff if d.startswith("-")]
    added = [d[1:].strip() for d in diff if d.startswith("+")]
    return (any(entry["removed"].strip() in line for line in removed)
            and any(entry["added"].strip() in line for line in added))


def run_module(module: str, workroot: Path, equivalent: dict) -> dict:
    work = workroot / module.replace("/", "_").removesuffix(".py")
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    scratch_copy(work, module)
    t0 = time.perf_counter()
    log = work / "mutmut.log"
    with open(log, "w") as fh:
        r = subprocess.run([sys.executable, "-m", "mutmut", "run", "--max-children", "1"], cwd=work,
                           env=mutmut_env(), stdout=fh, stderr=subprocess.STDOUT, check=False)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"{module}: mutmut run failed (exit {r.returncode}); see {log}")
    status = results(work)
    counts: dict[str, int] = {}
    for s in status.values():
        counts[s] = counts.get(s, 0) + 1
    survivors = []
    for name, s in sorted(status.items()):
        if s in DETECTED:
            continue
        diff = diff_of(work, name)
        why = next((e["why"] for e in equivalent.get(module, []) if matches(e, diff, name)), None)
        survivors.append({"name": name, "status": s, "diff": diff, "equivalent": why})
    n_equivalent = sum(1 for s in survivors if s["equivalent"])
    n = len(status)
    killed = counts.get(KILLED, 0)
    detected = sum(counts.get(k, 0) for k in DETECTED)
    score = detected / (n - n_equivalent) if n > n_equivalent else float("nan")
    return {"module": module, "tests": TESTS[module], "mutants": n, "killed": killed, "detected": detected,
            "counts": counts,
            "equivalent": n_equivalent, "score": score, "wall_s": round(wall, 1), "survivors": survivors}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--module", action="append", choices=sorted(TESTS), help="a module to mutate (repeatable; "
                    f"default: {', '.join(DEFAULT)})")
    ap.add_argument("--workdir", type=Path, help="where the scratch copies go (default: a temporary directory, "
                    "removed unless --keep)")
    ap.add_argument("--keep", action="store_true", help="keep the scratch copies (mutmut browse / show there)")
    ap.add_argument("--json", type=Path, default=Path("bench_mutation.json"))
    args = ap.parse_args(argv)
    try:
        import mutmut  # noqa: F401
    except ImportError:
        print("mutmut is not installed: pip install -e '.[mutation]'", file=sys.stderr)
        return 2
    modules = args.module or DEFAULT
    workroot = args.workdir or Path(tempfile.mkdtemp(prefix="emacheck-mutation-"))
    equivalent = load_equivalent()
    rows = []
    try:
        for m in modules:
            row = run_module(m, workroot, equivalent)
            rows.append(row)
            c = row["counts"]
            other = {k: v for k, v in c.items() if k not in (KILLED, SURVIVED, TIMEOUT)}
            print(f"{m:28s} {row['mutants']:4d} mutants, {row['killed']:4d} killed, {c.get(TIMEOUT, 0)} timeout, "
                  f"{c.get(SURVIVED, 0):3d} survived ({row['equivalent']} equivalent), other {other}; "
                  f"score {100 * row['score']:.1f} % of the non-equivalent; {row['wall_s']:.0f} s", flush=True)
            for s in row["survivors"]:
                if not s["equivalent"]:
                    print(f"    {s['name']} ({s['status']}): " + " | ".join(s["diff"]), flush=True)
    finally:
        if not args.keep and args.workdir is None:
            shutil.rmtree(workroot, ignore_errors=True)
    args.json.write_text(json.dumps({"mutmut": __import__("mutmut").__version__, "modules": rows}, indent=1))
    print(f"written to {args.json}" + (f"; scratch copies in {workroot}" if args.keep or args.workdir else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
