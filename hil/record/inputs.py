"""What a result was made from: every file an analysis read, by role, with its SHA-256 (``trace.inputs`` of
result.json, serv.json and diagnosis.json; docs/files.md).

An entry is ``{"role", "file", "sha256"}`` (sha256 None where the file cannot be read), with ``"part"`` where
the input is a part of the file (an actuation profile taken from meta.json's snapshot). The roles:
``recording`` (signals.csv, a bare CSV, a CAN log), ``run_record`` (meta.json: step times, the profiles'
snapshots, the seal), ``actuation_profile``, ``check_profile``, ``calibration`` (serv: the result.json whose LVDT
calibration was used), ``reference_*`` (diagnose: the same of the healthy reference) and ``history`` (diagnose
``--reference history``: the database the reference was looked up in; a server database is named, not hashed).
A check's own result names its recording only: the profiles and EDS it ran with are in ``files_sha256`` (hashed
when the check started) and its meta.json is still being written.
"""

from __future__ import annotations

from pathlib import Path

from hil.record.runfolder import record_path

#: roles, in the order a result lists them
ROLES = ("recording", "run_record", "actuation_profile", "check_profile", "calibration", "reference_recording",
         "reference_run_record", "reference_actuation_profile", "history")


def input_entry(role: str, path: Path, part: str | None = None) -> dict:
    """One input: its role, its path as given and the SHA-256 of its bytes (None: unreadable)."""
    from hil.record.seal import sha256_file

    out = {"role": role, "file": str(path), "sha256": sha256_file(Path(path))}
    if part:
        out["part"] = part
    return out


def profile_input(role: str, given: Path | None, run_dir: Path | None, snapshot: bool, shipped: str) -> dict:
    """The profile an analysis read: ``given`` (``--profile``/``--check``), else the run record's ``snapshot``
    (meta.json, part ``profiles.<kind>``), else the shipped file ``shipped``."""
    from hil.profile.load import default_profile_path

    if given is not None:
        return input_entry(role, Path(given))
    if snapshot and run_dir is not None:
        return input_entry(role, record_path(run_dir), part=f"profiles.{shipped.removesuffix('.toml')}")
    return input_entry(role, default_profile_path(shipped))


def recording_inputs(sig_path: Path, run_dir: Path | None, meta, profile: Path | None, *,
                     prefix: str = "") -> list[dict]:
    """The recording read, its run record (a run folder) and the actuation profile it was read with
    (:func:`hil.profile.load.actuation_of_recording`'s rule); ``prefix`` ``"reference_"`` for a reference."""
    out = [input_entry(prefix + "recording", sig_path)]
    if run_dir is not None and record_path(run_dir).is_file():
        out.append(input_entry(prefix + "run_record", record_path(run_dir)))
    snap = meta is not None and meta.profiles is not None and meta.profiles.actuation is not None
    out.append(profile_input(prefix + "actuation_profile", profile, run_dir, snap, "actuation.toml"))
    return out


def history_input(url: str) -> dict:
    """The wear history a reference was looked up in: an SQLite file hashed as it was, a server named
    (its password masked), not hashed."""
    from hil.profile.history_url import masked, sqlite_path

    if url.startswith("sqlite:"):
        return input_entry("history", sqlite_path(url))
    return {"role": "history", "file": masked(url), "sha256": None}
