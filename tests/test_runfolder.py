"""Run-folder CSV: round trip, and bad recordings refused with the line named."""

from __future__ import annotations

import numpy as np
import pytest

from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.errors import RecordingError
from hil.record.runfolder import SignalsWriter, read_signals

HEADER = "t,phi1,phi2,s1,s2,F1,F2\n"


def _write(tmp_path, body: str, header: str = HEADER):
    p = tmp_path / "sig.csv"
    p.write_text(header + body)
    return p


def test_writer_reader_round_trip(tmp_path):
    w = SignalsWriter(tmp_path / "signals.csv", flush_rows=3)
    sp = (Setpoint(DriveMode.POSITION, 1.25), Setpoint(DriveMode.FORCE, -2000.0))
    for k in range(10):
        smp = Sample(0.002 * (k + 1), 0.1 * k, -0.1 * k, 0.01 * k, -0.01 * k, 100.0 * k, -100.0 * k)
        w.write(smp, *sp, "cal1_sweep")
    w.close()
    sig = read_signals(tmp_path / "signals.csv")
    assert sig.n == 10
    np.testing.assert_allclose(sig.t, 0.002 * np.arange(1, 11))
    np.testing.assert_allclose(sig.F2, -100.0 * np.arange(10))
    assert list(sig.mode1) == [8.0] * 10 and list(sig.mode2) == [10.0] * 10
    assert sig.sp2[0] == -2000.0 and sig.step[0] == "cal1_sweep"
    assert sig.notes == ()


def test_truncated_last_line_is_dropped_and_noted(tmp_path):
    p = _write(tmp_path, "0.002,0,0,0,0,0,0\n0.004,0,0,0,0,0,0\n0.006,0,0,0.1")
    sig = read_signals(p)
    assert sig.n == 2
    assert "incomplete" in sig.notes[0]


@pytest.mark.parametrize("body,header,message", [
    ("0.002,0,0,0,0,0,0\n0.004,0,0,nan,0,0,0\n", HEADER, r"line 3: column 's1' \[mm\] is nan"),
    ("0.002,0,0,0,0,0,0\n0.004,0,0,abc,0,0,0\n", HEADER, r"line 3: column 's1': not a number: 'abc'"),
    ("0.002,0,0,0,0,0,0\n0.002,0,0,0,0,0,0\n", HEADER, r"line 3: time not increasing"),
    ("0.002,0,0,0,0,0\n", "t,phi1,phi2,s1,s2,F1\n", r"line 1: missing column\(s\) F2"),
    ("0.002,0,0,0,0,0,0,7\n", HEADER, r"line 2: 8 fields, header has 7"),
    ("", HEADER, r"no data rows"),
])
def test_bad_recordings(tmp_path, body, header, message):
    with pytest.raises(RecordingError, match=message):
        read_signals(_write(tmp_path, body, header))


def test_gap_is_noted(tmp_path):
    p = _write(tmp_path, "0.002,0,0,0,0,0,0\n0.004,0,0,0,0,0,0\n0.006,0,0,0,0,0,0\n0.020,0,0,0,0,0,0\n")
    assert "gap" in read_signals(p).notes[0]


def test_disk_sync_writes_json_in_order_off_the_thread_and_raises_its_errors(tmp_path):
    import json

    from hil.record.runfolder import DiskSync, SignalsWriter

    disk = DiskSync()
    w = SignalsWriter(tmp_path / "signals.csv")
    meta = {"steps": {}}
    for k in range(5):  # the loop mutates meta after handing it over: each write is a snapshot
        meta["steps"][f"s{k}"] = [float(k)]
        disk.write_json(tmp_path / "meta.json", meta)
        disk.fsync(w.fileno())
    disk.close()
    w.close()
    assert json.loads((tmp_path / "meta.json").read_text()) == {"steps": {f"s{k}": [float(k)] for k in range(5)}}
    assert not (tmp_path / "meta.json.tmp").exists() and not disk._thread.is_alive()
    bad = DiskSync()
    bad.write_json(tmp_path / "no-such-folder" / "meta.json", {})
    with pytest.raises(FileNotFoundError):
        bad.close()


def _calls_by_thread(monkeypatch) -> list[tuple[str, str]]:
    """Record (system call, thread name) of every os.write / os.fsync / os.close from now on."""
    import os
    import threading

    seen: list[tuple[str, str]] = []
    for name in ("write", "fsync", "close"):
        real = getattr(os, name)

        def spy(*a, _real=real, _name=name):
            seen.append((_name, threading.current_thread().name))
            return _real(*a)
        monkeypatch.setattr(os, name, spy)
    return seen


def test_signals_and_can_log_on_a_real_bus_make_no_system_call_on_the_loop_thread(tmp_path, monkeypatch):
    """With a background DiskSync (``emacheck run``), the loop's writes of signals.csv and the CAN log,
    their flushes, the fsync at a step change and the closes are all done by the sync thread, in order:
    the files read back whole."""
    import can

    from hil.canopen.frame import Frame
    from hil.record.canlog import CanLogWriter
    from hil.record.runfolder import DiskSync

    disk = DiskSync(background=True)
    w = SignalsWriter(tmp_path / "signals.csv", flush_rows=7, disk=disk)
    log = CanLogWriter(tmp_path / "can.log", flush_frames=5, disk=disk)
    seen = _calls_by_thread(monkeypatch)
    sp = Setpoint(DriveMode.POSITION, 0.5)
    for k in range(40):
        w.write(Sample(0.002 * (k + 1), 0.1, 0.2, 0.3, 0.4, 5.0, 6.0), sp, sp, "cal1_sweep")
        log.write(Frame(0x181, bytes([k, 1, 2])), 0.002 * (k + 1), rx=True)
        if k % 10 == 9:
            w.flush(0.002 * (k + 1), sync=True)
    log.close()
    w.close()
    disk.close()
    on_loop = [c for c in seen if c[1] != "emacheck-disk-sync"]
    assert on_loop == []
    assert {c[0] for c in seen} == {"write", "fsync", "close"} and len(seen) > 10
    sig = read_signals(tmp_path / "signals.csv")
    np.testing.assert_allclose(sig.t, 0.002 * np.arange(1, 41))
    frames = list(can.LogReader(str(tmp_path / "can.log")))
    assert [m.data[0] for m in frames] == list(range(40)) and frames[-1].timestamp == pytest.approx(0.080)


def test_without_a_background_disk_sync_each_flush_is_on_disk_at_once(tmp_path):
    """A dry-run (no thread): what was flushed is in the file when flush returns, what was not is not
    (a killed process loses only what it had not flushed); after a DiskSync closes, its jobs run at once."""
    from hil.record.runfolder import DiskSync, LoopFile

    f = LoopFile(tmp_path / "a.txt")
    f.write("one\n")
    assert (tmp_path / "a.txt").read_text() == ""
    f.flush()
    f.write("two\n")
    assert (tmp_path / "a.txt").read_text() == "one\n"
    f.close(sync=True)
    assert (tmp_path / "a.txt").read_text() == "one\ntwo\n" and f.closed
    disk = DiskSync(background=True)
    g = LoopFile(tmp_path / "b.txt", disk)
    g.write("x\n")
    g.flush()
    disk.close()
    assert (tmp_path / "b.txt").read_text() == "x\n"
    g.write("y\n")
    g.flush()  # the DiskSync is closed: at once
    assert (tmp_path / "b.txt").read_text() == "x\ny\n"
    g.close()
