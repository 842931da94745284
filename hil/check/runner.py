"""The check loop: sequence core + supervisor + run-folder logging over a link.

A *link* is whatever carries setpoints to the two drives and brings back one
synchronous sample per cycle: the plant directly (:class:`PlantLink`, for
``emacheck simulate``) or the CANopen master (``dry-run``/``run``). The loop
is the same for all of them, so the sequence core runs unchanged on hardware.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Protocol

from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.check.sequence import CheckSequence, CycleOutput, Progress, Step
from hil.check.supervisor import Supervisor
from hil.errors import KNOWN_ERRORS, LinkLostError, OutputError, RecordWriteError
from hil.profile.config import Actuation, Check
from hil.record.driveparts import DriveLast
from hil.record.runfolder import MetaWriter, SignalsWriter
from hil.record.runrecord import RunRecord, RunStatus, SafetyViolation, Stalls, StepTime
from hil.record.seal import seal_of
from hil.record.space import EndReserve, check_free_space, record_bytes

DISABLED = Setpoint(DriveMode.DISABLED, 0.0)
#: The reason recorded when the operator stops the check (Ctrl-C, SIGINT).
INTERRUPTED = "interrupted by the operator"


class Link(Protocol):
    """Carries setpoints to the two drives and returns the next synchronous sample.

    A link may also have (the loop reads them where it has): ``kept_limits`` (per EMA the limits its drive
    keeps itself: the supervisor's freshness limit), ``in_force`` (the setpoints the drives followed at the
    sample returned), ``behind`` (a stall's backlog: a newer sample is here already), ``stall_record()``
    (meta.json ``stalls``), ``preflight_record()``, ``force_by_position``, ``final_states``, ``timing``
    (:class:`hil.master.link.CanopenLink`).
    """

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
    status: RunStatus  #: done or aborted
    reason: str
    samples: int
    duration_s: float  #: rig (simulated or real) time
    steps: tuple[StepTime, ...]  #: when each step began and ended
    #: stopped by bad input found on the bus (two drives of one serial): the command exits 3, not 2
    bad_input: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", RunStatus(self.status))  # "done"/"aborted" as a RunStatus; else raises


def run_check(link: Link, act: Actuation, check: Check, meta: MetaWriter,
              on_cycle: Callable[[Progress, Sample], None] | None = None,
              max_duration_s: float | None = None) -> LoopOutcome:
    """Run the check over ``link``, logging every cycle into ``meta``'s run folder.

    The record is written to meta.json at the start and updated at each step change and at the end
    (``meta.record`` is the run's record then, also when this raises). Any exception aborts the
    sequence, stops both drives (DISABLED), closes the log and is re-raised; a record that can no longer be
    written (a full disk, an IO error) is such an exception, raised as :class:`hil.errors.RecordWriteError`
    after the drives' stop (exit 2). Before anything moves, the run folder's disk must hold the longest
    record the check may make (:func:`hil.record.space.check_free_space`, exit 3), and space for the record's
    end is kept (:class:`hil.record.space.EndReserve`). ``meta``'s DiskSync writes the record and fsyncs
    (unless one was given: in the background on a real bus, at once on simulated time); it is closed here.
    """
    meta.run_dir.mkdir(parents=True, exist_ok=True)
    # a drive without CST holds the calibration's opposing force by the sequence's position-mode loop
    seq = CheckSequence(act, check, force_by_position=getattr(link, "force_by_position", (False, False)))
    sup = Supervisor(act, check)
    rec = meta.write()
    limit = max_duration_s if max_duration_s is not None else 3.0 * seq.planned_duration_s() + 60.0
    reserve = _space_for(link, act, meta, rec, limit)
    # on a real bus, the signals' writes, fsync and the JSON files written in the loop: off the loop's
    # thread (the caller may have made the thread before it went real-time); on simulated time, at once
    meta.open_disk(background=getattr(link, "timing", None) is not None)
    writer = SignalsWriter(meta.run_dir / "signals.csv", disk=meta.disk)
    sp1 = sp2 = DISABLED
    smp: Sample | None = None
    t_start = 0.0
    record = getattr(link, "preflight_record", None)
    try:
        smp = link.first_sample()
        t_start = smp.t_s
        # the freshness limit from what the drives were confirmed to keep (hil.check.staleness)
        sup.drives_keep(getattr(link, "kept_limits", None))
        if record is not None:  # the layout, the scalings the drives reported, the drill: on disk now
            rec = meta.post(rec.with_preflight(record()))
        faults0 = _page_faults()
        while True:
            # each sample judged at its own SYNC's time against the setpoints its drives followed (after a
            # stall of the master, the last ones sent before it)
            in_force = getattr(link, "in_force", None) or (sp1, sp2)
            viol = sup.check(smp, *in_force)
            if viol is not None:
                if rec.safety is None:
                    rec = replace(rec, safety=SafetyViolation.of(viol))
                out: CycleOutput = seq.abort(smp.t_s, f"safety limit {viol.key}: {viol.detail}")
            elif smp.t_s - t_start > limit:
                out = seq.abort(smp.t_s, f"check exceeded {limit:.0f} s")
            elif getattr(link, "behind", False):
                # a stall's backlog: a newer sample is here already, this one's setpoints would never reach
                # the drives; the sequence steps on the newest, its profile holding over the stall as the
                # drives held (no step in the setpoints), and this row records what they followed
                out = CycleOutput(*in_force, seq.step_now, ())
            else:
                out = seq.step(smp)
            writer.write(smp, out.sp1, out.sp2, out.step.value)
            if smp.t_s - writer.flushed_t_s >= FLUSH_PERIOD_S:
                writer.flush(smp.t_s)
                _still_writing(meta)
            if out.events:
                for ev in out.events:
                    rec = rec.with_step(ev.step.value, ev.t_s)
                    if ev.step is Step.ABORTED:
                        link.abort()
                writer.flush(smp.t_s, sync=True)  # to the OS and the disk (by the sync thread on a real bus)
                rec = meta.post(rec)
            if on_cycle is not None:
                on_cycle(seq.progress(smp.t_s), smp)
            sp1, sp2 = out.sp1, out.sp2
            if seq.finished:
                link.exchange(DISABLED, DISABLED)
                break
            smp = link.exchange(sp1, sp2)
        link.close()
        rec, stop_note = _record_safe_state(link, rec)
        rec = _record_last_seen(link, smp, t_start, act, rec)
        # the cyclic loop touches no new memory (a page fault costs ~0.9 ms in user-mode-linux)
        loop_page_faults = _page_faults() - faults0
        reserve.release()
        meta.close_disk()
        writer.close()
        rec = replace(rec, recording_sha256=seal_of(meta.run_dir))  # the recording as the check left it
    except BaseException as exc:
        reserve.release()  # first: the space the record's end needs
        reason = _stop_after(exc, seq, link, smp, rec, record, meta, writer, t_start, act)
        if isinstance(exc, OSError) and not isinstance(exc, KNOWN_ERRORS):
            raise RecordWriteError(f"{reason}; the drives were stopped first") from exc
        raise
    status = RunStatus.DONE if seq.step_now == Step.DONE else RunStatus.ABORTED
    reason = (seq.abort_reason + stop_note) if seq.abort_reason else stop_note.lstrip("; ")
    rec = meta.write(rec.ended(status, reason, writer.rows, smp.t_s - t_start, loop_page_faults=loop_page_faults,
                               stalls=_stalls(link)))
    return LoopOutcome(status, reason, writer.rows, smp.t_s - t_start, rec.steps)


def _space_for(link, act: Actuation, meta: MetaWriter, rec: RunRecord, limit_s: float) -> EndReserve:
    """Before anything moves: the run folder's disk holds the longest record the check may make (else its
    record says aborted and why, :class:`hil.errors.OutputError`, exit 3), and the space for the record's
    end is kept."""
    fpc = float(getattr(link, "frames_per_cycle", 0.0))
    try:
        check_free_space(meta.run_dir, record_bytes(limit_s, act.timing.sync_period_s, fpc),
                         f"{limit_s:.0f} s at most, one row of signals.csv and {fpc:.1f} frames of can.log every "
                         f"{act.timing.sync_period_s * 1e3:g} ms, and the record's end")
    except OutputError as exc:
        meta.write(rec.ended(RunStatus.ABORTED, f"not started: {exc}", 0, 0.0))
        raise
    return EndReserve(meta.run_dir)


def _still_writing(meta: MetaWriter) -> None:
    """A write the disk's thread could not make (a full disk, an IO error): stop the check now."""
    disk = meta.disk
    err = disk.error if disk is not None else None
    if err is not None:
        raise RecordWriteError(f"the record cannot be written any more: {type(err).__name__}: {err}")


def _stop_after(exc: BaseException, seq, link, smp, rec: RunRecord, record, meta: MetaWriter, writer,
                t_start: float, act: Actuation) -> str:
    """Fail closed after ``exc``: stop both drives, keep what can be kept of the log, record why; the reason."""
    reason = (str(exc) or INTERRUPTED) if isinstance(exc, KeyboardInterrupt) else \
        f"error: {type(exc).__name__}: {exc}"
    secondary = ""
    try:
        seq.abort(smp.t_s if smp is not None else 0.0, reason)
        link.abort()
        if smp is not None:
            link.exchange(DISABLED, DISABLED)
    except LinkLostError:  # the interface is gone: no quick stop can be sent, the drives stop by themselves
        secondary = "; while stopping: the CAN interface still gone, no quick stop sent"
    except Exception as exc2:  # the original error is re-raised; this one is recorded
        secondary = f"; while stopping: {type(exc2).__name__}: {exc2}"
    finally:
        try:
            link.close()
        except Exception as exc3:
            secondary += f"; while closing the link: {type(exc3).__name__}: {exc3}"
        rec, note = _record_safe_state(link, rec)
        secondary += note
        try:
            rec = _record_last_seen(link, smp, t_start, act, rec)
        except Exception as exc6:  # (the stop is recorded without it)
            secondary += f"; while recording where the drives were last seen: {type(exc6).__name__}: {exc6}"
        if record is not None and rec.master_loss is None:  # the preflight stopped: what it got to, the drill's
            try:                                            # outcome and the identities read included
                rec = rec.with_preflight(record())
            except Exception as exc5:
                secondary += f"; while recording the preflight: {type(exc5).__name__}: {exc5}"
        for what, close in (("the run folder", meta.close_disk), ("signals.csv", writer.close)):
            try:
                close()
            except OSError as exc4:
                secondary += f"; while writing {what}: {type(exc4).__name__}: {exc4}"
        meta.write(rec.ended(RunStatus.ABORTED, reason + secondary, writer.rows,
                             (smp.t_s - t_start) if smp is not None else 0.0, stalls=_stalls(link),
                             recording_sha256=seal_of(meta.run_dir)))
    return reason + secondary


def _stalls(link) -> Stalls | None:
    """The master's stalls as the link saw them (:meth:`hil.master.link.CanopenLink.stall_record`); None for a
    link without (the plant)."""
    record = getattr(link, "stall_record", None)
    return None if record is None else Stalls.from_json(record(), "stalls")


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


def _record_last_seen(link, smp: Sample | None, t_start: float, act: Actuation, rec: RunRecord) -> RunRecord:
    """The record with where each drive was last seen (:class:`hil.record.driveparts.DriveLast`): the last
    complete sample (the link's ``last_sample``, the safe stop's included; else the loop's last), its time from
    the check's start, and the EMCYs each drive sent (the link's ``emcy_report()``; none for the plant)."""
    sample = getattr(link, "last_sample", None) or smp
    if sample is None:
        return rec
    report = getattr(link, "emcy_report", None)
    last = DriveLast.of(sample, t_start, act.mechanics.i_total_rad_per_mm, report() if report is not None else None)
    return replace(rec, drives_last=last)


def _record_safe_state(link, rec: RunRecord) -> tuple[RunRecord, str]:
    """The record with the drives' final states (:attr:`CanopenLink.final_states`), and a note for the
    abort reason naming any drive that could not be brought to the safe state."""
    final = getattr(link, "final_states", None)
    if not final:
        return rec, ""
    rec = rec.with_final_states(final, getattr(link, "close_errors", None))
    bad = [d.unsafe_note(k) for k, d in rec.drives_final.items() if not d.safe]
    return rec, (f"; not in the safe state: {', '.join(bad)}" if bad else "")
