"""Results into the history: one result file recorded into an open store, recording after a check (never
raises), and ``emacheck history sync`` over run folders and result files.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

from hil.history.record import load_result, record_from_result
from hil.record.seal import sha256_file


def record_file(store, path: Path, *, run_folder: Path | None = None, recording: Path | None = None) -> bool:
    """Record one result file into an open store; True if new, False if already recorded."""
    result = load_result(path)
    rec_sha = sha256_file(recording) if recording is not None and not (result.get("trace") or {}).get("run_id") \
        else None
    return store.add(record_from_result(result, result_path=path, run_folder=run_folder, recording_sha256=rec_sha))


def results_in(path: Path) -> list[tuple[Path, Path | None]]:
    """The result files to record for a ``history sync`` argument: ``(result file, run folder)``.

    A run folder gives its result.json and those of its ``analysis-*/`` and ``serv-*/`` sub-folders
    (every result kept; the trend takes the latest analysis of each run); a folder written with
    ``--out`` its result.json / serv.json; a file itself.
    """
    from hil.errors import RecordingError
    from hil.record.runfolder import has_record

    path = Path(path)
    if path.is_file():
        return [(path, path.parent if has_record(path.parent) else None)]
    if not path.is_dir():
        raise RecordingError(f"{path}: no such run folder or result file")
    run = path if has_record(path) else None
    found = [(p, run) for p in (path / "result.json", path / "serv.json") if p.is_file()]
    for sub in sorted(path.iterdir()):
        if sub.is_dir() and (sub.name.startswith("analysis-") or sub.name.startswith("serv-")):
            found += [(p, run or path) for p in (sub / "result.json", sub / "serv.json") if p.is_file()]
    found += [(p, run) for p in sorted(path.glob("*.result.json")) + sorted(path.glob("*.serv.json"))]
    if not found:
        raise RecordingError(f"{path}: holds no result.json or serv.json to record")
    return found


def sync(store, paths: Iterable[Path], say: Callable[[str], None]) -> tuple[int, int]:
    """``emacheck history sync``: record every result of ``paths``; returns (new, already there)."""
    new = old = 0
    for arg in paths:
        for res, run in results_in(Path(arg)):
            if record_file(store, res, run_folder=run):
                new += 1
                say(f"recorded: {res}")
            else:
                old += 1
                say(f"already recorded: {res}")
    return new, old


def record_after_check(url: str, result_path: Path, *, run_folder: Path | None, recording: Path | None,
                       say: Callable[[str], None]) -> bool:
    """Record a result just written, after the check: one line either way, never raises.

    The check's own outcome and exit status do not depend on it: a database that is down,
    locked or refuses the login leaves the result in its folder and says how to record it later.
    """
    from hil.profile.history_url import masked

    later = run_folder if run_folder is not None else result_path
    try:
        from hil.history.store import HistoryStore

        with HistoryStore.open(url) as store:
            new = record_file(store, result_path, run_folder=run_folder, recording=recording)
    except Exception as exc:  # noqa: BLE001 - the check is done and kept; recording must not change its outcome
        from hil.errors import HistoryError

        why = str(exc) if isinstance(exc, HistoryError) else f"{type(exc).__name__}: {exc}"
        say(f"NOT recorded in the history: {why}; the result is kept in {result_path}; record it later with "
            f"`emacheck history sync {later}`")
        return False
    from hil.history.record import load_result, unidentified

    try:
        unknown = unidentified(load_result(result_path))
    except Exception:  # noqa: BLE001 - recorded already; only the words below depend on it
        unknown = []
    say(f"{'recorded in' if new else 'already recorded in'} the history {masked(url)}"
        + (f"; in no trend: the identity of {' and '.join(unknown)} is unknown (not an actuator)" if unknown else ""))
    return True
