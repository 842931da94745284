"""The run record (hil/record/runrecord.py): meta.json as frozen dataclasses, its JSON both ways, its one
writer (hil/record/runfolder.py: MetaWriter).

Unit tests of the record (round trip, the layout the format has had, a killed run's partial record,
malformed fields named, illegal statuses refused), and a source check that no module of the product
but hil/record/runfolder.py writes meta.json and none but hil/record/runrecord.py names the file (an AST walk, as
tests/test_layers.py walks the imports).
"""

from __future__ import annotations

import ast
import dataclasses
import json
from pathlib import Path

import pytest

from hil.cli import main
from hil.errors import KNOWN_ERRORS, RecordingError, RunRecordError
from hil.record.cycletiming import CycleTiming
from hil.record.runfolder import MetaWriter, read_record
from hil.record.runrecord import (
    Attribution,
    Bus,
    BusLoad,
    CanStats,
    DriveFinal,
    Identity,
    Installation,
    Profiles,
    RunMode,
    RunRecord,
    RunStatus,
    SafetyViolation,
    Software,
    StepTime,
    Timing,
    Wear,
    start_record,
)

ROOT = Path(__file__).resolve().parents[1]
ML = {"consumer_heartbeat_ms": 125, "master_node_id": 127, "configured": True, "problems": []}


def _timing() -> Timing:
    ct = CycleTiming(2e-3)
    for k in range(50):
        t = k * 2e-3
        ct.sync(t)
        ct.work(t + 1e-4, t + 3e-4 + (k % 7) * 1e-5, cpu_s=1.5e-4)
        ct.answered(t + 4e-4 + (k % 5) * 2e-5)
    return Timing(ct.summary(), t0_unix_s=1.7e9, sync="loop-timed", sync_skipped=1, sync_late_max_ms=0.25,
                  sync_periods_skipped=2)


def _full(**over) -> RunRecord:
    """A record with every field set (as an `emacheck run` that tripped a limit would leave it)."""
    rec = RunRecord(
        run_id="0123abcd", software=Software("emacheck", "0.1.0"), started_utc="2026-01-02T03:04:05+00:00",
        status=RunStatus.ABORTED, profiles=Profiles({"name": "a"}, {"safety": {"max_force_N": 9e3}}),
        steps=(StepTime("enable", 0.014, 0.514), StepTime("approach", 0.514, 1.0), StepTime("aborted", 1.0)),
        mode=RunMode.RUN, scenario="gust", seed=7, realtime=False, bus=Bus("socketcan", "can0", 500_000),
        simrig={"stroke_limit_mm": 20.0}, truth={"backlash_mm": {"int1": 0.1}}, faults=({"kind": "runaway"},),
        bus_load=BusLoad(0.35, 0.43), eds="/p/ema.eds", eds_nodes={"ema1": "/p/ema.eds", "io": "/p/io.eds"},
        plan_notes=("note one",), force_control={"ema1": "cst", "ema2": "csp"},
        attribution=Attribution("Ann", None), installation=Installation("D-ABCD", None, "rig 2", 1500.0, 900),
        files_sha256={"actuation": "ab" * 32}, wear=Wear(1500.0, {"scatter_mm": 0.002}, {"int1": 0.1375}),
        process_image={"pdos": [], "channels": []}, master_loss={"ema1": ML},
        identity={"ema1": Identity(1, 3642, 1026, 65536, 99), "ema2": None},
        safety=SafetyViolation("max_force_N", "EMA 1 force 9.1 kN > 9 kN", 0.9, 9100.0, 9000.0),
        drives_final={"ema1": DriveFinal(1, "SWITCH_ON_DISABLED", True, True, True, ML),
                      "ema2": DriveFinal(2, "FAULT", False, False, False)},
        stop_errors=("SdoTimeout: node 2",), loop_page_faults=3, reason="safety limit max_force_N: ...",
        ended_utc="2026-01-02T03:05:00+00:00", samples=500, duration_s=1.0, wall_s=1.5,
        can=CanStats(4000, 0, 1, 2, max_lag_ms=0.4, page_faults=12), timing=_timing())
    return dataclasses.replace(rec, **over)


def test_round_trip_of_a_full_record_through_json_text(tmp_path):
    rec = _full()
    assert RunRecord.from_json(rec.as_json()) == rec
    meta = MetaWriter(tmp_path, rec)
    assert meta.write() is rec and meta.path == tmp_path / "meta.json"
    assert read_record(tmp_path) == rec  # through json.dumps and json.loads, as a reader sees it
    assert read_record(tmp_path / "nowhere") is None and read_record(None) is None


def test_json_layout_order_absent_keys_and_the_two_historical_placements():
    j = _full().as_json()
    assert list(j)[:8] == ["run_id", "software", "started_utc", "status", "profiles", "steps", "mode", "scenario"]
    # the parts spread flat, in place; loop_page_faults inside can; identity after the preflight's image
    assert list(j)[10:13] == ["interface", "channel", "bitrate_bps"]
    assert list(j)[-7:] == ["reason", "ended_utc", "samples", "duration_s", "wall_s", "can", "timing"]
    assert "loop_page_faults" not in j and j["can"]["loop_page_faults"] == 3
    assert list(j).index("identity") == list(j).index("master_loss") + 1
    assert j["steps"] == {"enable": [0.014, 0.514], "approach": [0.514, 1.0], "aborted": [1.0]}
    assert j["identity"]["ema2"] is None and j["status"] == "aborted" and type(j["status"]) is str
    assert j["operator"] == "Ann" and j["work_order"] is None and j["flight_cycles"] == 900
    # a CANopen run stopped before its preflight: identity comes with the CAN statistics, last
    assert list(_full(process_image=None, master_loss=None).as_json())[-1] == "identity"
    # a simulated run: no preflight, no CAN statistics
    sim = _full(process_image=None, master_loss=None, can=None, timing=None, bus=None, safety=None).as_json()
    assert sim["loop_page_faults"] == 3 and list(sim).index("loop_page_faults") == list(sim).index("stop_errors") + 1
    assert list(sim).index("identity") == list(sim).index("files_sha256") + 1 < list(sim).index("wear")
    assert not {"interface", "safety", "can", "timing", "process_image"} & set(sim)
    # fields that are None are absent, those of a part spread flat stay (null) while the part is there
    bare = RunRecord(run_id="x", attribution=Attribution()).as_json()
    assert bare == {"run_id": "x", "operator": None, "work_order": None}


def test_the_bus_part_keeps_the_multicast_hop_limit_only_where_there_is_one():
    udp = Bus("udp_multicast", "239.74.0.1", 500_000, 0)
    assert udp.as_json() == {"interface": "udp_multicast", "channel": "239.74.0.1", "bitrate_bps": 500_000,
                             "multicast_hops": 0}
    assert Bus.from_json(udp.as_json()) == udp
    sock = Bus("socketcan", "can0", 500_000)
    assert "multicast_hops" not in sock.as_json() and Bus.from_json(sock.as_json()) == sock
    rec = _full(bus=udp)
    assert rec.as_json()["multicast_hops"] == 0 and RunRecord.from_json(rec.as_json()) == rec
    with pytest.raises(RunRecordError, match="multicast_hops"):
        Bus.from_json({**udp.as_json(), "multicast_hops": "0"})


def test_identity_without_0x1018_sub_4_has_no_serial_key():
    listed = Identity.of(1, {"vendor_id": 1, "product_code": 2, "revision": 3, "serial": None})
    unlisted = Identity.of(1, {"vendor_id": 1, "product_code": 2, "revision": 3})
    assert listed.as_json()["serial"] is None and "serial" not in unlisted.as_json()
    assert Identity.from_json(unlisted.as_json()) == unlisted and Identity.of(1, {}) is None


def test_timing_is_the_cycle_timing_summary_as_its_producer_writes_it():
    """Timing's JSON is hil.record.cycletiming's summary JSON plus the SYNC's own keys, read back whole (the
    CPU time's histogram, which that JSON leaves out, is not kept)."""
    t = _timing()
    summary = t.summary
    assert summary.reaction.histogram and summary.work_cpu.n == 50 and summary.work_cpu.histogram == ()
    j = t.as_json()
    assert list(j)[-5:] == ["t0_unix_s", "sync", "sync_skipped", "sync_late_max_ms", "sync_periods_skipped"]
    assert j["sync_skipped"] == 1 and j["sync_periods_skipped"] == 2
    older = {k: v for k, v in j.items() if k != "sync_periods_skipped"}  # a record from before the field
    assert Timing.from_json(older).sync_periods_skipped is None and Timing.from_json(older).as_json() == older
    assert {k: v for k, v in j.items() if k in summary.as_json()} == summary.as_json()
    assert Timing.from_json(j) == t and Timing.from_json(json.loads(json.dumps(j))) == t
    with pytest.raises(RunRecordError, match=r"field 'timing.gap.histogram.bins': expected \[\[lower edge"):
        Timing.from_json({**j, "gap": {**j["gap"], "histogram": {"bin_ms": 0.01, "bins": [[0.1]]}}}, "timing")
    with pytest.raises(RunRecordError, match=r"field 'timing.reaction.worst\[0\].cycle': missing"):
        Timing.from_json({**j, "reaction": {**j["reaction"], "worst": [{"ms": 1.0, "t_s": 0.1}]}}, "timing")


@pytest.mark.slow
def test_the_default_dry_runs_meta_json_reads_and_writes_back_byte_for_byte(dry_run):
    """The whole record of a real run (the session's default dry-run): read, written again as the
    writer writes it, the same bytes: nothing lost, nothing added, the keys in their order."""
    out, rc = dry_run
    text = (out / "meta.json").read_text()
    rec = read_record(out)
    assert rc == 0 and rec.status is RunStatus.DONE and rec.mode is RunMode.DRY_RUN
    assert rec.steps[-1] == StepTime("done", rec.steps[-2].t_end_s) and rec.can.frames_logged > 0
    assert isinstance(rec.loop_page_faults, int) and all(d.safe for d in rec.drives_final.values())
    assert json.dumps(rec.as_json(), indent=2) + "\n" == text


def test_a_killed_runs_partial_record_reads():
    """meta.json of a master killed in the calibration: still running, the last step open, no end."""
    j = {"run_id": "ab", "software": {"name": "emacheck", "version": "0.1.0"}, "started_utc": "2026-01-02",
         "status": "running", "profiles": {"actuation": {}, "check": {}},
         "steps": {"enable": [0.014, 0.514], "approach": [0.514, 1.024], "cal1_load": [1.024]},
         "mode": "dry-run", "seed": 7, "operator": None, "work_order": None, "files_sha256": {}}
    rec = RunRecord.from_json(j)
    assert rec.status is RunStatus.RUNNING and rec.mode is RunMode.DRY_RUN
    assert rec.steps[-1] == StepTime("cal1_load", 1.024) and rec.steps[0].t_end_s == 0.514
    assert rec.reason is None and rec.ended_utc is None and rec.samples is None and rec.drives_final is None
    assert rec.attribution == Attribution() and rec.installation is None
    assert rec.as_json() == j  # nothing added, nothing lost
    assert RunRecord.from_json({"truth": {"backlash_mm": {}}}) == RunRecord(truth={"backlash_mm": {}})


@pytest.mark.parametrize("change, field, words", [
    ({"steps": {"cal1_sweep": [2.5, "x"]}}, "steps.cal1_sweep", "[t_start, t_end]"),
    ({"steps": {"enable": []}}, "steps.enable", "[t_start, t_end]"),
    ({"drives_final": {"ema2": {"node": 2, "state": "FAULT", "reachable": True, "confirmed": True,
                                "safe": "yes"}}}, "drives_final.ema2.safe", "true or false"),
    ({"identity": {"ema1": {"vendor_id": 1, "product_code": 2, "revision": 3}}}, "identity.ema1.node", "missing"),
    ({"can": {"frames_logged": "many", "missing_cycles": 0, "bad_frames": 0, "unknown_frames": 0}},
     "can.frames_logged", "an integer"),
    ({"can": {"frames_logged": 1, "missing_cycles": 0, "bad_frames": 0, "unknown_frames": 0,
              "loop_page_faults": 1.5}}, "can.loop_page_faults", "an integer"),
    ({"seed": "7"}, "seed", "an integer"),
    ({"seed": True}, "seed", "an integer"),
    ({"duration_s": "1 s"}, "duration_s", "a number"),
    ({"software": "emacheck"}, "software", "a JSON object"),
    ({"interface": "socketcan", "channel": "can0"}, "bitrate_bps", "missing"),
    ({"files_sha256": {"actuation": 5}}, "files_sha256", "an object of strings"),
    ({"mode": "replay"}, "mode", "not one of dry-run, run, simulate, simulate-scenario"),
])
def test_a_malformed_field_is_named(change, field, words):
    with pytest.raises(RunRecordError) as e:
        RunRecord.from_json({"run_id": "ab", "status": "done", **change}, "/x/meta.json")
    assert e.value.field == field and words in str(e.value)
    assert str(e.value).startswith(f"/x/meta.json: field '{field}': ")
    assert isinstance(e.value, RecordingError) and isinstance(e.value, KNOWN_ERRORS)


def test_an_illegal_status_is_refused_from_json_and_in_python():
    with pytest.raises(RunRecordError, match="field 'status': 'finished' is not one of running, done, aborted"):
        RunRecord.from_json({"status": "finished"})
    with pytest.raises(RunRecordError, match="'status'"):
        RunRecord(status="finished")
    assert RunRecord(status="done").status is RunStatus.DONE
    with pytest.raises(RunRecordError, match=r"field '\(top level\)': expected a JSON object"):
        RunRecord.from_json([1, 2])


def test_a_key_from_the_link_or_master_the_record_has_no_field_for_is_refused_not_dropped():
    """Where the record is built from another module's JSON (the link's preflight record, the master's
    final states, the preflight's identity), a key added there without a field here fails loudly."""
    rec = RunRecord()
    pre = {"process_image": {"pdos": []}, "master_loss": {}, "identity": {"ema1": {"node": 1, "vendor_id": 1,
                                                                                   "product_code": 2, "revision": 3}}}
    assert rec.with_preflight(pre).identity["ema1"] == Identity(1, 1, 2, 3, serial_listed=False)
    with pytest.raises(RunRecordError, match="preflight record: field 'bus_errors': no field of the run record"):
        rec.with_preflight({**pre, "bus_errors": 3})
    with pytest.raises(RunRecordError, match="field 'identity.ema1.firmware'"):
        rec.with_preflight({**pre, "identity": {"ema1": {**pre["identity"]["ema1"], "firmware": "1.2"}}})
    final = {"node": 2, "state": "FAULT", "reachable": True, "confirmed": True, "safe": False, "master_loss": {}}
    assert rec.with_final_states({"ema2": final}, []).drives_final["ema2"].state == "FAULT"
    with pytest.raises(RunRecordError, match="final states: field 'drives_final.ema2.temperature_C'"):
        rec.with_final_states({"ema2": {**final, "temperature_C": 40.0}}, None)
    with pytest.raises(RunRecordError, match=r"preflight: field 'identity \(node 3\).hw'"):
        Identity.of(3, {"vendor_id": 1, "product_code": 2, "revision": 3, "hw": 1})


def test_steps_start_and_close_as_the_loop_reports_them():
    rec = RunRecord(steps=())
    rec = rec.with_step("enable", 0.0).with_step("approach", 0.5).with_step("aborted", 0.7)
    assert rec.steps == (StepTime("enable", 0.0, 0.5), StepTime("approach", 0.5, 0.7), StepTime("aborted", 0.7))
    again = rec.with_step("aborted", 0.9)  # a step that ran before is not added twice; the open one closes
    assert again.steps[-1] == StepTime("aborted", 0.7, 0.9) and len(again.steps) == 3


def test_start_record_and_the_end_of_the_loop(actuation, check_profile):
    rec = start_record(actuation, check_profile, mode=RunMode.SIMULATE, seed=3)
    assert rec.status is RunStatus.RUNNING and rec.steps == () and len(rec.run_id) == 32
    assert rec.software.name == "emacheck" and rec.profiles.check["safety"]["max_force_N"] > 0
    assert start_record(actuation, check_profile, status=RunStatus.DONE).status is RunStatus.DONE
    end = rec.ended("aborted", "why", 10, 0.02, loop_page_faults=0)
    assert (end.status, end.reason, end.samples, end.duration_s, end.loop_page_faults) == \
        (RunStatus.ABORTED, "why", 10, 0.02, 0) and end.ended_utc is not None and rec.reason is None


def test_the_writer_posts_through_its_disk_sync_and_then_writes_at_once(tmp_path):
    from hil.record.runfolder import DiskSync

    meta = MetaWriter(tmp_path, RunRecord(run_id="a", status="running", steps=()))
    meta.open_disk(background=True)
    disk = meta.disk
    for k in range(4):
        meta.post(meta.record.with_step(f"s{k}", float(k)))
    meta.close_disk()  # waits for every queued write
    assert meta.disk is None and not disk._thread.is_alive()
    assert read_record(tmp_path) == meta.record and len(meta.record.steps) == 4
    meta.post(meta.record.ended("done", "", 4, 3.0))  # no DiskSync any more: at once
    assert read_record(tmp_path).status is RunStatus.DONE
    given = DiskSync(background=False)
    meta2 = MetaWriter(tmp_path, RunRecord(), given)
    meta2.open_disk(background=True)
    assert meta2.disk is given  # one given (emacheck run makes it before going real-time) is kept


def test_analyze_names_the_bad_field_of_a_run_folders_meta_json(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "signals.csv").write_text("t,phi1,phi2,s1,s2,F1,F2\n" + "".join(
        f"{k * 0.002:.4f},0,0,0,0,0,0\n" for k in range(1, 20)))
    (run / "meta.json").write_text(json.dumps({"status": "done", "steps": {"enable": "0.5"}}))
    assert main(["analyze", str(run), "--out", str(tmp_path / "out")]) == 3
    err = capsys.readouterr().err
    assert f"{run / 'meta.json'}: field 'steps.enable': expected [t_start, t_end]" in err
    assert "Traceback" not in err


# ---------------------------------------------------------------- one writer of meta.json

WRITERS = {"write_json_atomic", "write_json", "write_text", "write_bytes", "dump"}


def _meta_json_writes(path: Path) -> list[tuple[int, str, str]]:
    """(line, kind, what) of each place a module names the file meta.json (kind "name": the string, or
    ``hil.record.runrecord.META_NAME``) or hands something named meta to a file writer (kind "write":
    ``write_json_atomic``, ``DiskSync.write_json``, ``write_text``, ``json.dump``, ``open(..., "w")``)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and node.value == "meta.json":
            out.append((node.lineno, "name", "the file name 'meta.json'"))
        if (isinstance(node, ast.Name) and node.id == "META_NAME") or (
                isinstance(node, ast.ImportFrom) and any(a.name == "META_NAME" for a in node.names)):
            out.append((node.lineno, "name", "META_NAME"))
        if not isinstance(node, ast.Call):
            continue
        name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
        opens = name == "open" and any(isinstance(a, ast.Constant) and isinstance(a.value, str)
                                       and set(a.value) & set("wax+") for a in node.args[1:2])
        if name in WRITERS or opens:
            for a in [*node.args, *(k.value for k in node.keywords), node.func]:
                names = [n.id for n in ast.walk(a) if isinstance(n, ast.Name)] + \
                        [n.attr for n in ast.walk(a) if isinstance(n, ast.Attribute)]
                if any("meta" in n.lower() for n in names if n != name):
                    out.append((node.lineno, "write", f"{name}(...) of {ast.unparse(a)}"))
    return out


def test_the_meta_json_check_sees_what_it_is_meant_to(tmp_path):
    p = tmp_path / "m.py"
    p.write_text("import json\n"
                 "def a(out, meta):\n    write_json_atomic(out / 'meta.json', meta)\n"
                 "def b(disk, meta_path, rec):\n    disk.write_json(meta_path, rec)\n"
                 "def c(run, meta):\n    with open(run.meta_file, 'w') as fh:\n        json.dump(meta, fh)\n"
                 "def d(out, result):\n    write_json_atomic(out / 'result.json', result)\n"
                 "def e(run):\n    return open(run.meta_file).read()\n"
                 "from hil.record.runrecord import META_NAME\n"
                 "def f(run, rec):\n    p = run / META_NAME\n    write_json_atomic(p, rec)\n")
    assert sorted({(ln, kind) for ln, kind, _ in _meta_json_writes(p)}) == \
        [(3, "name"), (3, "write"), (5, "write"), (7, "write"), (8, "write"), (13, "name"), (15, "name")]


def test_no_module_but_the_writer_writes_meta_json():
    """meta.json is written by hil/record/runfolder.py (MetaWriter, read_record) and named there and in
    hil/record/runrecord.py (META_NAME) only."""
    writer, record = ROOT / "hil" / "record" / "runfolder.py", ROOT / "hil" / "record" / "runrecord.py"
    allowed = {"write": {writer}, "name": {writer, record}}
    found = [f"{p.relative_to(ROOT)}:{ln}: {what}"
             for p in sorted(q for pkg in ("hil", "blf", "sim") for q in (ROOT / pkg).rglob("*.py"))
             for ln, kind, what in _meta_json_writes(p) if p not in allowed[kind]]
    assert not found, ("meta.json outside hil.record.runfolder.MetaWriter / hil.record.runrecord.META_NAME:\n"
                       + "\n".join(found))
