"""The vcan stage: `sim-serve` and `run` as two processes over SocketCAN vcan0.

Runs tests/vcan/vcan_check_traffic.py (the whole check over vcan0 against the
simulator's truth, a can-utils candump capture against the master's log,
SIGKILL of sim-serve, SIGKILL of run mid force fight: the drives stop by
themselves) where SocketCAN is:

* on the host kernel, if it has vcan (``vcan0`` exists or can be created);
* else inside user-mode-linux (Debian packages user-mode-linux, kmod,
  can-utils; see tests/vcan/vcan_stage.py), failing if the tests fail there;
* else the stage is skipped with the reason (never passed silently); under CI=true it fails with
  the reason instead (tests/support/ci.py: CI must run this stage).

Inside UML (``EMACHECK_INSIDE_UML=1``) the stage never boots another UML.
"""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "vcan"))

import vcan_stage  # noqa: E402

from support.ci import skip_or_fail  # noqa: E402

# one vcan stage (vcan0 or a user-mode-linux guest) per host; started first (tests/conftest.py)
pytestmark = pytest.mark.xdist_group("vcan")

INNER = "tests/vcan/vcan_check_traffic.py"
#: The inner tests take ~130 s inside UML (2026-11-27, issue 38: a whole check of ~56 s of real time
#: and ~30 s around it, one killed after 3 s and one after ~14 s of check, each process starting in
#: 2.5-5 s there); bounds, not targets. ``--durations=0`` prints where the inner time goes.
INNER_TIMEOUT_S = 600.0
#: the whole check's run folder inside an attempt's kept folder (vcan_check_traffic.py's full_check)
WHOLE_CHECK_RUN = Path("vcan-check0") / "run"


def _stopped_by_a_stall(keep: Path) -> bool:
    """Whether the attempt's whole check ended on the master's stall rule (hil.master.link raises
    StaleData: the master fell behind the bus by more than the stall budget), read from its run record."""
    import json

    meta = keep / WHOLE_CHECK_RUN / "meta.json"
    try:
        rec = json.loads(meta.read_text())
    except (OSError, ValueError):
        return False
    return rec.get("status") == "aborted" and "StaleData: sensor data stale" in str(rec.get("reason"))
UML_TIMEOUT_S = 660.0


def _inner_cmd(basetemp: Path) -> list[str]:
    return [sys.executable, "-m", "pytest", "-q", "-s", "-p", "no:cacheprovider", "-o", "addopts=-ra", "--durations=0",
            INNER, "--basetemp", str(basetemp)]


def _inner_cmd_uml(keep: Path) -> list[str]:
    """Inside UML the run folders and captures go to tmpfs (/dev/shm): on hostfs every write
    and the run folder's fsync (meta.json at each step change) are host system calls that hold
    the guest's only CPU, and the master's cycle with it. They are copied to ``keep`` after."""
    inner = "/dev/shm/emacheck-vcan"
    cmd = " ".join(shlex.quote(c) for c in _inner_cmd(Path(inner)))
    return ["sh", "-c", f"{cmd}; rc=$?; cp -a {inner} {shlex.quote(str(keep))} 2>/dev/null; exit $rc"]


@pytest.mark.vcan
@pytest.mark.slow
def test_vcan_stage(tmp_path):
    mode, why = vcan_stage.stage_mode()
    if mode == "skip":
        skip_or_fail(f"vcan stage skipped: {why}")
    if mode == "host":
        try:
            r = subprocess.run(_inner_cmd(tmp_path / "inner"), cwd=vcan_stage.ROOT, capture_output=True,
                               text=True, timeout=INNER_TIMEOUT_S)
        except subprocess.TimeoutExpired as exc:
            pytest.fail(f"vcan tests on the host kernel did not end within {INNER_TIMEOUT_S} s:\n{exc.stdout}")
        print(r.stdout[-2000:])
        assert r.returncode == 0, f"vcan tests on the host kernel failed:\n{r.stdout[-8000:]}\n{r.stderr[-2000:]}"
        return
    assert not vcan_stage.inside_uml()  # stage_mode never answers "uml" inside UML
    # UML's single CPU is two host processes handing over at each system call; a busy host can
    # stall it for tens of milliseconds, and the check then aborts on a safety limit exactly as
    # a rig would. A failed attempt is repeated once (both are reported); a real fault fails twice.
    # A third attempt only where both failed ones were stopped by the master's own stall rule
    # (_stopped_by_a_stall: the stall budget, 100 ms here, was exceeded): the project's CI host stopped this
    # VM for over 100 ms in one of two attempts on 2026-11-29 (docs/vcan.md), which no budget the
    # product allows can absorb; any other failure still fails after two.
    failed: list[vcan_stage.UmlResult] = []
    for attempt in (1, 2, 3):
        if attempt == 3 and not all(_stopped_by_a_stall(tmp_path / f"inner{a}") for a in (1, 2)):
            break
        res = vcan_stage.run_in_uml(_inner_cmd_uml(tmp_path / f"inner{attempt}"), tmp_path / f"uml{attempt}",
                                    UML_TIMEOUT_S)
        print(f"user-mode-linux attempt {attempt}: vcan0 up "
              f"{res.boot_s if res.boot_s is not None else float('nan'):.1f} s after start, "
              f"{res.wall_s:.1f} s in all, exit {res.status} ({why})")
        print(res.output[-2000:])
        if res.status == 0 or res.status == vcan_stage.SETUP_FAILED or res.status is None or res.timed_out:
            break
        failed.append(res)
    first = failed[0] if failed and failed[0] is not res else None
    assert not res.timed_out, f"user-mode-linux did not halt within {UML_TIMEOUT_S} s:\n{res.output[-8000:]}"
    assert res.status is not None, (f"no exit status from inside user-mode-linux; console:\n{res.console_tail}\n"
                                    f"output:\n{res.output[-4000:]}")
    assert res.status != vcan_stage.SETUP_FAILED, f"vcan setup inside user-mode-linux failed:\n{res.output}"
    assert res.status == 0, (f"vcan tests inside user-mode-linux failed {len(failed)} times (exit {res.status}):\n"
                             f"{res.output[-8000:]}\nfirst attempt:\n{first.output[-4000:] if first else ''}")


def test_serve_answers_sync_and_stops_on_event():
    """hil.sim_server.serve on a python-can virtual bus: boot-up, one TPDO set per SYNC, clean stop."""
    import threading

    import can
    import numpy as np

    from hil.profile.load import load_simrig
    from hil.sim_server import serve
    from sim.plant import RigPlant
    from support.canopen_rig import make_pair

    simrig = load_simrig()
    pair = make_pair(RigPlant(simrig.params, np.random.default_rng(1)))
    channel = "emacheck-test-serve"
    master = can.Bus(interface="virtual", channel=channel)
    stop = threading.Event()
    ready = threading.Event()
    out: dict = {}
    # period_s: this test sends its SYNCs at its own pace, not every 2 ms; with 0.002 the synchronous window
    # (0.9 x 2 ms) was shorter than a thread hand-over on a loaded machine (the GIL's 5 ms switch interval),
    # the TPDOs were discarded as late (CiA 301 0x1007; test_loop_sync.py pins that) and the test failed
    # in 1 of 12 runs beside two busy loops. 0.5 s: a window no scheduler delay of this machine reaches.
    th = threading.Thread(target=lambda: out.update(stats=serve(
        can.Bus(interface="virtual", channel=channel), pair, stop=stop, on_ready=ready.set, period_s=0.5)))
    th.start()
    try:
        assert ready.wait(10)
        boot = sorted((m.arbitration_id, bytes(m.data)) for m in (master.recv(2), master.recv(2)))
        assert boot == [(0x701, b"\x00"), (0x702, b"\x00")]
        master.send(can.Message(arbitration_id=0x000, data=[0x01, 0], is_extended_id=False))  # NMT start
        got = []
        for _ in range(3):
            master.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
            deadline = 2.0
            ids = []
            while len([i for i in ids if i in (0x181, 0x182, 0x281, 0x282)]) < 4:
                m = master.recv(deadline)
                assert m is not None, ids
                ids.append(m.arbitration_id)
            got.append(sorted(i for i in ids if i in (0x181, 0x182, 0x281, 0x282)))
        assert got == [[0x181, 0x182, 0x281, 0x282]] * 3
    finally:
        stop.set()
        th.join(10)
        master.shutdown()
    assert not th.is_alive()
    st = out["stats"]
    assert st.syncs == 3 and st.plant_steps == 4 and st.frames_rx == 4 and st.send_errors == 0
    assert st.tpdos_sent == 12 and st.tpdos_discarded == 0 and st.frames_tx >= 2 + 12
    # the loop's timing: every SYNC a cycle, answered (TPDOs out), its handling timed, SYNC to SYNC twice
    tm = st.timing
    assert (tm.cycles, tm.reaction.n, tm.work.n, tm.work_cpu.n, tm.gap.n, tm.unanswered) == (3, 3, 3, 3, 2, 0)
    assert 0.0 < tm.work.max_ms <= tm.reaction.max_ms
    assert st.as_json()["timing"]["reaction"]["n"] == 3 and "ready" not in st.lines()[0]


def test_serve_with_a_sensor_node_boots_and_answers_it(tmp_path):
    """hil.sim_server.serve with the rig's CiA 401 node (tests/support/sensor_rig.py): its boot-up, its SDO
    server (identity 0x1018:01) and its default event TPDO once operational, on a python-can virtual bus."""
    import struct
    import threading

    import can
    import numpy as np

    from hil.canopen.frame import Frame
    from hil.canopen.sdo import SdoClient, SdoEvent
    from hil.profile.load import load_simrig
    from hil.sim_server import serve
    from sim.plant import RigPlant
    from support.canopen_rig import make_pair
    from support.sensor_rig import sensor_rig

    _, rig = sensor_rig(tmp_path / "actuation.toml")
    pair = make_pair(RigPlant(load_simrig().params, np.random.default_rng(1)), rig)
    channel = "emacheck-test-serve-sensor"
    master = can.Bus(interface="virtual", channel=channel)
    stop, ready = threading.Event(), threading.Event()
    out: dict = {}
    # period_s: this test sends its SYNCs at its own pace, not every 2 ms; with 0.002 the synchronous window
    # (0.9 x 2 ms) was shorter than a thread hand-over on a loaded machine (the GIL's 5 ms switch interval),
    # the TPDOs were discarded as late (CiA 301 0x1007; test_loop_sync.py pins that) and the test failed
    # in 1 of 12 runs beside two busy loops. 0.5 s: a window no scheduler delay of this machine reaches.
    th = threading.Thread(target=lambda: out.update(stats=serve(
        can.Bus(interface="virtual", channel=channel), pair, stop=stop, on_ready=ready.set, period_s=0.5)))
    th.start()
    try:
        assert ready.wait(10)
        boot = sorted((m.arbitration_id, bytes(m.data)) for m in (master.recv(2), master.recv(2), master.recv(2)))
        assert boot == [(0x701, b"\x00"), (0x702, b"\x00"), (0x703, b"\x00")]
        client = SdoClient(3)
        req = client.start_upload(0x1018, 1, 0.0)
        master.send(can.Message(arbitration_id=req.arbitration_id, data=req.data, is_extended_id=False))
        m = master.recv(2)
        assert m is not None and m.arbitration_id == 0x583
        ev = client.on_frame(Frame(m.arbitration_id, bytes(m.data)), 0.0)
        assert isinstance(ev, SdoEvent) and struct.unpack("<I", ev.data)[0] == 0x0E3A
        master.send(can.Message(arbitration_id=0x000, data=[0x01, 3], is_extended_id=False))  # start node 3
        ids = sorted(m.arbitration_id for m in (master.recv(2), master.recv(2)))
        assert ids == [0x283, 0x383]  # its EDS default: TPDO2 and TPDO3 event driven, sent on entering
    finally:
        stop.set()
        th.join(10)
        master.shutdown()
    assert not th.is_alive() and out["stats"].send_errors == 0


@pytest.mark.parametrize("meta, third", [
    ({"status": "aborted", "reason": "error: StaleData: sensor data stale: the master is 102 ms behind the bus"}, True),
    ({"status": "aborted", "reason": "error: StaleData: sensor data stale: no complete sample for 11 SYNC cycles"},
     True),
    ({"status": "aborted", "reason": "safety limit max_force_N: 2318 N"}, False),
    ({"status": "done", "reason": ""}, False),
    (None, False),
])
def test_only_a_whole_check_stopped_by_the_stall_rule_earns_a_third_attempt(tmp_path, meta, third):
    """The stage's third attempt is for a check the master stopped on its stall rule (the host stopped the
    VM longer than the budget), read from the whole check's run record; anything else fails after two."""
    import json

    run = tmp_path / WHOLE_CHECK_RUN
    run.mkdir(parents=True)
    if meta is not None:
        (run / "meta.json").write_text(json.dumps(meta))
    assert _stopped_by_a_stall(tmp_path) is third
