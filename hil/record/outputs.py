"""Where a command's outputs go, never over what is there: a check's new run folder, an analysis's new
sub-folder or new file names (:class:`Outputs`, created exclusively through :mod:`hil.record.runfolder`),
the UTC stamps they are named with, and the sha256 of the files a result was made from.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass
from pathlib import Path


def utc_stamp() -> str:
    """The current UTC time as ``20261123T141500Z`` (for folder names)."""
    return _dt.datetime.now(_dt.UTC).strftime("%Y%m%dT%H%M%SZ")


def utc_iso() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


@dataclass(frozen=True)
class Outputs:
    """Where a command writes its files: a folder and a prefix for the file names.

    Its files are created, never written over an existing one (:meth:`write_json`, :meth:`write_with`),
    unless ``own``: a run's own result.json and report.html, written into its run folder during the run.
    """

    folder: Path
    prefix: str = ""
    own: bool = False
    made: bool = False  #: the folder was made for these outputs (:meth:`discard_if_empty` may remove it)

    def path(self, name: str) -> Path:
        """The path of output ``name`` (e.g. ``"result.json"``)."""
        return self.folder / f"{self.prefix}{name}"

    def discard_if_empty(self) -> None:
        """After a command failed before writing: remove the folder it made for its outputs, if still empty."""
        if self.made:
            import contextlib

            with contextlib.suppress(OSError):
                self.folder.rmdir()  # (fails, and is left, where anything was written into it)

    def write_json(self, name: str, obj) -> Path:
        """Output ``name`` as JSON: created (:class:`hil.errors.OutputError` if it exists), or for ``own``
        replaced atomically."""
        from hil.record.runfolder import create_json, write_json_atomic

        path = self.path(name)
        if self.own:
            write_json_atomic(path, obj)
            return path
        return create_json(path, obj)

    def write_with(self, name: str, write) -> Path:
        """Output ``name`` written by ``write(path)`` (a report writer): created under a temporary name and
        linked to its own only if that does not exist; for ``own`` written in place."""
        from hil.record.runfolder import create_with

        path = self.path(name)
        if self.own:
            write(path)
            return path
        return create_with(path, write)


def output_stem(path: Path) -> str:
    """The name an analysis of a bare recording is named after: a ``.csv`` file's stem (``flight.csv`` ->
    ``flight``), any other recording's whole name (``flight.csv.gz``, ``flight.log``), so that two
    recordings beside each other never share their outputs' names."""
    if path.name.lower().endswith(".csv") and len(path.name) > 4:
        return path.name[:-4]
    return path.name


def make_folder(folder: Path) -> Path:
    """Make ``folder`` (and its parents); :class:`hil.errors.OutputError` naming it if it cannot be made."""
    from hil.errors import OutputError
    from hil.record.runfolder import output_error

    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputError(f"{folder}: a file, not a folder; give --out a new or empty folder") from None
    except OSError as exc:
        raise output_error(folder, exc) from None
    if not folder.is_dir():
        raise OutputError(f"{folder}: a file, not a folder; give --out a new or empty folder")
    return folder


def new_folder(parent: Path, name: str) -> Path:
    """A new folder ``parent/name`` (``name-2``, ``name-3`` ... where it exists), made here and now (mkdir
    is exclusive: two commands in the same second get two folders)."""
    from hil.record.runfolder import output_error

    make_folder(parent)
    k = 1
    while True:
        folder = Path(parent) / (name if k == 1 else f"{name}-{k}")
        try:
            folder.mkdir()
            return folder
        except FileExistsError:
            k += 1
        except OSError as exc:
            raise output_error(folder, exc) from None


def is_empty_folder(path: Path) -> bool:
    """True for a folder that holds nothing."""
    try:
        return path.is_dir() and next(path.iterdir(), None) is None
    except OSError:
        return False


def fresh_outputs(out: Path, kind: str) -> Outputs:
    """``--out`` of a command that derives files (analyze, serv, diagnose, history): a new or empty folder
    is used as it is; a folder that holds files already (a run folder, an earlier analysis) gets a new
    sub-folder ``<kind>-<UTC time>/``, so nothing in it is written over; a file is refused (exit 3)."""
    from hil.errors import OutputError

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out}: a file, not a folder; give a new or empty folder (or omit --out)")
    if not out.exists() or is_empty_folder(out):
        made = not out.exists()
        return Outputs(make_folder(out), made=made)
    return Outputs(new_folder(out, f"{kind}-{utc_stamp()}"), made=True)


def outputs_for(out: Path | None, recording: Path, run_dir: Path | None, kind: str,
                names: tuple[str, ...] = ()) -> Outputs:
    """Where an analysis of a recording writes, never over what is there: ``--out`` as
    :func:`fresh_outputs` says; for a run folder a new sub-folder ``<kind>-<UTC time>/`` (the check's own
    result stays untouched); for a bare file, files named after it next to it (``flight.csv`` ->
    ``flight.result.json``; ``flight.2.result.json`` where any of ``names`` exists already, then
    ``flight.3.`` ...). The files are created exclusively (:meth:`Outputs.write_json`)."""
    if out is not None:
        return fresh_outputs(out, kind)
    if run_dir is not None:
        return Outputs(new_folder(run_dir, f"{kind}-{utc_stamp()}"), made=True)
    stem, folder = output_stem(recording), recording.parent
    k = 1
    while True:
        prefix = f"{stem}." if k == 1 else f"{stem}.{k}."
        if not any((folder / f"{prefix}{n}").exists() or (folder / f"{prefix}{n}").is_symlink() for n in names):
            return Outputs(folder, prefix=prefix)
        k += 1


def file_hashes(**paths: Path | None) -> dict[str, str]:
    """SHA-256 of each named file (a profile given as None: the shipped one), for traceability."""
    from hil.profile.load import default_profile_path
    from hil.record.seal import sha256_file

    defaults = {"actuation": "actuation.toml", "check": "check.toml", "simrig": "simrig.toml"}
    out = {}
    for name, path in paths.items():
        if path is None:
            if name not in defaults:
                continue
            path = default_profile_path(defaults[name])
        out[name] = sha256_file(Path(path)) or ""
    return out


def default_out(kind: str) -> Path:
    """``emacheck-runs/<local time>-<kind>``, made here (``-2``, ``-3`` ... for a second one in the same
    second): where a command writes when ``--out`` is not given."""
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    return new_folder(Path("emacheck-runs"), f"{stamp}-{kind}")


def check_new_run_folder(out: Path | None) -> None:
    """``--out`` of a check (run, dry-run, simulate): a check's record is written once, so a folder that
    holds anything, or a file, is refused (:class:`hil.errors.OutputError`, exit 3) before anything
    is done; a new or empty folder is fine."""
    from hil.errors import OutputError

    if out is None:
        return
    out = Path(out)
    hint = "choose another, or omit --out for a new folder emacheck-runs/<time>-<command>"
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out}: a file, not a run folder; {hint}")
    if out.is_dir() and not is_empty_folder(out):
        raise OutputError(f"--out {out}: the folder holds files already (a check's record is written once, "
                          f"never into another's); {hint}")


def out_dir(out: Path | None, kind: str) -> Path:
    """The run folder of a check, made: ``out`` (``--out``) if it is new or empty
    (:func:`check_new_run_folder`), else :func:`default_out`."""
    if out is not None:
        check_new_run_folder(out)
        return make_folder(Path(out))
    return default_out(kind)
