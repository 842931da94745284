"""The check loop: sequence core + supervisor + run-folder logging over a link.

A *link* is whatever carries setpoints to the two drives and brings back one
synchronous sample per cycle: the plant directly (:class:`PlantLink`, for
``emacheck simulate``) or the CANopen master (``dry-run``/``run``). The loop
is the same for all of them, so the sequence core runs unchanged on hardware.
"""

from __future__ import annotations

import datetime as _dt
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from hil import __version__
from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.config import Actuation, Check
from hil.profiles import actuation_tables, snapshot
from hil.runfolder import DiskSync, SignalsWriter, write_json_atomic
from hil.sequence import CheckSequence, CycleOutput, Progress, Step
from hil.supervisor import Supervisor

DISABLED = Setpoint(DriveMode.DISABLED, 0.0)
#: The reason recorded when the operator stops the check (Ctrl-C, SIGINT).
INTERRUPTED = "interrupted by the operator"


class Link(Protocol):
    """Carries setpoints to the two drives and returns the next synchronous sample."""

    def first_sample(self) -> Sample: ...

    def exchange(self, sp1: Setpoint, sp2: Setpoint) -> Sample: ...

    def abort(self) -> None:
        """The check aborted: the next DISABLED setpoints mean a quick stop."""

    def close(self) -> None: ...


class PlantLink:
    """The simulated plant as a link, no CAN in between (``emacheck simulate``)."""

    def __init__(self, plant) -> None:  # sim.plant.RigPlant
        self.plant = plant

    def first_sample(self) -> Sample:
        return self.plant.step(DISABLED, DISABLED)

    def exchange(self, sp1: Setpoint, sp2: Setpoint) -> Sample:
        return self.plant.step(sp1, sp2)

    def abort(self) -> None:
        pass

    def close(self) -> None:
        pass


@dataclass(frozen=True)
class LoopOutcome:
    status: str  #: "done" or "aborted"
    reason: str
    samples: int
    duration_s: float  #: rig (simulated or real) time
    steps: dict  #: step name -> [t_start, t_end]


def _now_iso() -> str:
    return _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")


def start_meta(act: Actuation, check: Check, extra: dict) -> dict:
    """The meta.json content at the start of a run (with a new run id)."""
    return {
        "run_id": uuid.uuid4().hex,
        "software": {"name": "emacheck", "version": __version__},
        "started_utc": _now_iso(),
        "status": "running",
        "profiles": {"actuation": actuation_tables(act), "check": snapshot(check)},
        "steps": {},
        **extra,
    }


def run_check(link: Link, act: Actuation, check: Check, run_dir: Path, meta: dict,
              on_cycle: Callable[[Progress, Sample], None] | None = None,
              max_duration_s: float | None = None, disk: DiskSync | None = None) -> LoopOutcome:
    """Run the check over ``link``, logging every cycle into ``run_dir``.

    ``meta`` is written to meta.json at the start and updated at each step
    change and at the end. Any exception aborts the sequence, stops both
    drives (DISABLED), closes the log and is re-raised. ``disk`` writes the
    run folder's JSON and fsyncs (default: in the background on a real bus,
    at once on simulated time); it is closed here.
    """
    run_dir.mkdir(parents=True, exist_ok=True)
    # a drive without CST holds the calibration's opposing force by the sequence's position-mode loop
    seq = CheckSequence(act, check, force_by_position=getattr(link, "force_by_position", (False, False)))
    sup = Supervisor(act, check)
    writer = SignalsWriter(run_dir / "signals.csv")
    meta_path = run_dir / "meta.json"
    write_json_atomic(meta_path, meta)
    # on a real bus, fsync and the JSON files written in the loop: off the loop's thread (the caller
    # may have made the thread before it went real-time); on simulated time, at once
    if disk is None:
        disk = DiskSync(background=getattr(link, "timing", None) is not None)
    limit = max_duration_s if max_duration_s is not None else 3.0 * seq.planned_duration_s() + 60.0
    sp1 = sp2 = DISABLED
    steps: dict[str, list[float]] = {}
    smp: Sample | None = None
    t_start = 0.0
    try:
        smp = link.first_sample()
        t_start = smp.t_s
        record = getattr(link, "preflight_record", None)
        if record is not None:  # the layout, the scalings the drives reported, the drill: on disk now
            meta.update(record())
            disk.write_json(meta_path, meta)
        faults0 = _page_faults()
        while True:
            viol = sup.check(smp, sp1, sp2)
            if viol is not None:
                if "safety" not in meta:
                    meta["safety"] = {"limit": viol.limit, "detail": viol.detail, "t_s": viol.t_s,
                                      "value": viol.value, "threshold": viol.threshold}
                out: CycleOutput = seq.abort(smp.t_s, f"safety limit {viol.limit}: {viol.detail}")
            elif smp.t_s - t_start > limit:
                out = seq.abort(smp.t_s, f"check exceeded {limit:.0f} s")
            else:
                out = seq.step(smp)
            writer.write(smp, out.sp1, out.sp2, out.step.value)
            if smp.t_s - writer.flushed_t_s >= FLUSH_PERIOD_S:
                writer.flush(smp.t_s)
            if out.events:
                for ev in out.events:
                    for v in steps.values():
                        if len(v) == 1:
                            v.append(ev.t_s)
                    steps.setdefault(ev.step.value, [ev.t_s])
                    if ev.step is Step.ABORTED:
                        link.abort()
                writer.flush(smp.t_s)  # to the OS now, to the disk by the sync thread
                disk.fsync(writer.fileno())
                meta["steps"] = steps
                disk.write_json(meta_path, meta)
            if on_cycle is not None:
                on_cycle(seq.progress(smp.t_s), smp)
            sp1, sp2 = out.sp1, out.sp2
            if seq.finished:
                link.exchange(DISABLED, DISABLED)
                break
            smp = link.exchange(sp1, sp2)
        link.close()
        stop_note = _record_safe_state(link, meta)
    except BaseException as exc:
        # fail closed: stop both drives, keep the log, record why, re-raise
        reason = INTERRUPTED if isinstance(exc, KeyboardInterrupt) else f"error: {type(exc).__name__}: {exc}"
        secondary = ""
        try:
            seq.abort(smp.t_s if smp is not None else 0.0, reason)
            link.abort()
            if smp is not None:
                link.exchange(DISABLED, DISABLED)
        except Exception as exc2:  # the original error is re-raised; this one is recorded
            secondary = f"; while stopping: {type(exc2).__name__}: {exc2}"
        finally:
            try:
                link.close()
            except Exception as exc3:
                secondary += f"; while closing the link: {type(exc3).__name__}: {exc3}"
            secondary += _record_safe_state(link, meta)
            try:
                disk.close()
            except OSError as exc4:
                secondary += f"; while writing the run folder: {type(exc4).__name__}: {exc4}"
            writer.close()
            meta.update(status="aborted", reason=reason + secondary, ended_utc=_now_iso(), steps=steps,
                        samples=writer.rows, duration_s=(smp.t_s - t_start) if smp is not None else 0.0)
            write_json_atomic(meta_path, meta)
        raise
    # the cyclic loop touches no new memory (a page fault costs ~0.9 ms in user-mode-linux)
    meta["loop_page_faults"] = _page_faults() - faults0
    disk.close()
    writer.close()
    status = "done" if seq.step_now == Step.DONE else "aborted"
    reason = (seq.abort_reason + stop_note) if seq.abort_reason else stop_note.lstrip("; ")
    meta.update(status=status, reason=reason, ended_utc=_now_iso(), steps=steps,
                samples=writer.rows, duration_s=smp.t_s - t_start)
    write_json_atomic(meta_path, meta)
    return LoopOutcome(status, reason, writer.rows, smp.t_s - t_start, steps)


def _page_faults() -> int:
    """Page faults of this process so far (minor and major; 0 where the OS does not count them)."""
    try:
        import resource
    except ImportError:  # (not on Windows)
        return 0
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_minflt + r.ru_majflt


#: The run folder's signals are flushed to the OS at least every this much check time [s]
#: (and fsynced at every step change): a killed master loses at most this much.
FLUSH_PERIOD_S = 0.5


def _record_safe_state(link, meta: dict) -> str:
    """Put the drives' final states (:attr:`CanopenLink.final_states`) into meta; returns a
    note for the abort reason naming any drive that could not be brought to the safe state."""
    final = getattr(link, "final_states", None)
    if not final:
        return ""
    meta["drives_final"] = final
    errs = getattr(link, "close_errors", None)
    if errs:
        meta["stop_errors"] = errs[:10]
    bad = [f"EMA {k[-1]} (node {v['node']}) "
           + ("unreachable (heartbeat lost), last known state " if not v["reachable"] else
              "state not confirmed (no statusword), last known " if not v["confirmed"] else "in ")
           + v["state"] for k, v in final.items() if not v["safe"]]
    return f"; not in the safe state: {', '.join(bad)}" if bad else ""
