"""The drill's outcome and the identity are always in the record (issue 36 parts 2 and 3).

A dry-run refused by the master's-death drill (both drives ignore it; also the foreign drive logic that
waits in Not ready to switch on for a controlword) keeps each drive's drill result in meta.json, in
result.json and on the console, both drives end in Switch on disabled confirmed by a read after the stop,
and the identity read in the preflight is recorded. A drive whose EDS has 0x1016 but no 0x6007 (an external
watchdog stated) is told exactly that, with no field of a configuration that was not written.
"""

from __future__ import annotations

import dataclasses
import json
import re

import pytest
from rich.console import Console

from hil.cli.console import print_master_loss
from hil.cli.dry_run import dry_run
from hil.master.core import MasterCore
from hil.record.runfolder import read_record
from hil.record.runrecord import RunRecord
from sim.faults import Fault

WATCHDOG = "STO of both drives dropped by the rig's watchdog relay 100 ms after the master's last heartbeat"


def _refused(tmp_path, actuation, check_profile, simrig, faults):
    console = Console(record=True, width=400, force_terminal=False)
    r = dry_run(actuation, check_profile, simrig, tmp_path / "run", faults=faults, console=console)
    return r, read_record(r.out), json.loads((r.out / "result.json").read_text()), console.export_text()


@pytest.mark.parametrize("foreign", [False, True], ids=["ready", "not-ready-until-controlword"])
def test_a_refused_drill_keeps_both_drives_outcome_in_every_record(tmp_path, actuation, check_profile, simrig,
                                                                   foreign):
    faults = [Fault("ignore_abort_connection", 1), Fault("ignore_abort_connection", 2)]
    if foreign:
        faults += [Fault("not_ready_until_controlword", 1), Fault("not_ready_until_controlword", 2)]
    r, meta, res, text = _refused(tmp_path, actuation, check_profile, simrig, faults)
    assert r.exit_code == 2 and r.injector.syncs == 0  # no check ran
    assert "node 1 (EMA 1): did not react to the master's death" in meta.reason
    assert "node 2 (EMA 2): did not react either" in meta.reason
    for k in (1, 2):
        ml = meta.master_loss[f"ema{k}"]
        assert ml["configured"] is True and ml["consumer_heartbeat_ms"] == 125
        drill = ml["drill"]
        assert drill["outcome"] == "no reaction" and drill["emcy"] == ["0x8130"]
        assert drill["waited_ms"] >= 2 * 125
        assert res["trace"]["master_loss"][f"ema{k}"] == ml  # result.json holds the same
        line = next(ln for ln in text.splitlines() if ln.startswith(f"EMA {k} reaction to losing the master:"))
        assert f"NO REACTION: still OPERATION ENABLED after {drill['waited_ms']} ms" in line and "0x8130" in line
        fin = meta.drives_final[f"ema{k}"]  # down by SDO, and read again after that
        assert (fin.state, fin.confirmed, fin.safe) == ("SWITCH_ON_DISABLED", True, True)
        assert re.fullmatch(r"read after the stop at t = \d+\.\d{3} s", fin.seen)
        ident = meta.identity[f"ema{k}"]  # read in the preflight, recorded in a refused run too
        assert ident is not None and (ident.node, ident.vendor_id) == (k, actuation.canopen.vendor_id)
        assert res["trace"]["identity"][f"ema{k}"]["product_code"] == actuation.canopen.product_code
    assert {n.state_machine.state.name for n in r.injector.pair.nodes} == {"SWITCH_ON_DISABLED"}
    report = (r.out / "report.html").read_text()  # nothing to analyse: the report still says what the drill saw
    for k in (1, 2):
        assert f"ema{k} reaction to losing the master" in report
    assert report.count("drill: NO REACTION: still OPERATION ENABLED") == 2


def test_a_drive_with_0x1016_but_no_0x6007_is_told_exactly_that_and_nothing_unwritten_is_recorded(tmp_path, simrig):
    import numpy as np
    from test_master import Pump, _variant

    from sim.plant import RigPlant
    from support.canopen_rig import make_pair

    act, rig = _variant(tmp_path, eds_remove=[0x6007], canopen={"external_watchdog": WATCHDOG})
    m = MasterCore(act, rig.plan)
    p = Pump(m, make_pair(RigPlant(simrig.params, np.random.default_rng(4)), rig))
    p.preflight()
    js = m.drives[1].master_loss.as_json()
    assert js["problems"] == ["its EDS has no writable 0x6007:00 (abort connection option code): nothing written"]
    assert "0x1016" not in js["problems"][0]
    for absent in ("consumer_heartbeat_ms", "master_node_id", "abort_connection_option"):
        assert absent not in js
    assert js["configured"] is False and js["drill"]["outcome"] == "not configured"
    assert js["external_watchdog"] == WATCHDOG
    # the console says the drill was not run and why the rig is protected all the same
    console = Console(record=True, width=400, force_terminal=False)
    print_master_loss(console, RunRecord(master_loss={"ema1": js}))
    assert console.export_text().strip() == (
        "EMA 1 reaction to losing the master: NOT configured: its EDS has no writable 0x6007:00 (abort connection "
        f"option code): nothing written; not drilled; external watchdog stated: {WATCHDOG}")


def test_with_an_external_watchdog_the_console_and_record_say_the_drill_saw_no_reaction(actuation, simrig):
    import numpy as np
    from test_master import Pump, _master

    from sim.plant import RigPlant
    from support.canopen_rig import make_pair

    act = dataclasses.replace(actuation, canopen=dataclasses.replace(actuation.canopen, external_watchdog=WATCHDOG))
    pair = make_pair(RigPlant(simrig.params, np.random.default_rng(4)))
    pair.nodes[1].connection_lost = lambda: None
    m = _master(act)
    Pump(m, pair).preflight()
    js = m.drives[2].master_loss.as_json()
    console = Console(record=True, width=400, force_terminal=False)
    print_master_loss(console, RunRecord(master_loss={"ema2": js}))
    out = console.export_text()
    assert "drill: NO REACTION: still OPERATION ENABLED" in out and f"external watchdog stated: {WATCHDOG}" in out


# ------------------------------------------------------------------ identity (part 3)


def _no_identity_subs(tmp_path, **canopen):
    """The shipped rig with a drive EDS that lists only 0x1018:01 (CiA 301: :02, :03, :04 optional)."""
    from hil.profile.load import load_actuation
    from hil.profile.rig import plan_for
    from support.eds import write_eds_variant
    from support.profiles import write_profile_variant

    tmp_path.mkdir(exist_ok=True)
    eds = write_eds_variant(tmp_path / "drive.eds", remove_subs=[(0x1018, 2), (0x1018, 3), (0x1018, 4)])
    text = eds.read_text()  # and its [DeviceInfo] silent on them too: nothing to compare offline
    for name in ("ProductNumber", "RevisionNumber"):
        text = re.sub(rf"^{name}=.*$", f"{name}=0", text, flags=re.M)
    eds.write_text(text)
    prof = write_profile_variant("actuation.toml", tmp_path / "actuation.toml",
                                 {"canopen": {"eds": str(eds), **canopen}})
    act = load_actuation(prof)
    return act, plan_for(act, prof)  # no refusal for the optional sub-indices


def _preflight(act, plan, pair):
    from test_master import Pump

    m = MasterCore(act, plan)
    p = Pump(m, pair)
    p.preflight()
    return m, p


def test_identity_the_eds_leaves_out_is_read_from_the_drive_and_checked(tmp_path, simrig):
    import numpy as np

    from sim.plant import RigPlant
    from support.canopen_rig import make_pair

    act, rig = _no_identity_subs(tmp_path)
    pair = make_pair(RigPlant(simrig.params, np.random.default_rng(5)))  # drives that do have :02..:04
    m, p = _preflight(act, rig.plan, pair)
    assert p.sdo_reads(1)[:4] == [(0x1018, 1), (0x1018, 2), (0x1018, 3), (0x1018, 4)]
    ident = m.preflight.identities[1]
    assert (ident["product_code"], ident["revision"]) == (act.canopen.product_code, pair.nodes[0].read(0x1018, 3))
    assert ident["serial"] == pair.nodes[0].read(0x1018, 4)
    # and compared with the profile: another product code is refused, naming it
    from hil.master.core import PreflightError

    other, other_rig = _no_identity_subs(tmp_path / "other", product_code=0x403)
    with pytest.raises(PreflightError, match=r"node 1 \(EMA 1\): identity 0x1018 vendor 0x00000E3A product "
                                             r"0x00000402 does not match the profile \(canopen.vendor_id 0x00000E3A, "
                                             r"canopen.product_code 0x00000403\)"):
        _preflight(other, other_rig.plan, make_pair(RigPlant(simrig.params, np.random.default_rng(5))))


def test_identity_a_drive_refuses_is_recorded_not_read_and_not_compared(tmp_path, simrig):
    import numpy as np

    from hil.record.runrecord import Identity
    from sim.plant import RigPlant
    from support.canopen_rig import make_pair

    act, rig = _no_identity_subs(tmp_path)
    pair = make_pair(RigPlant(simrig.params, np.random.default_rng(6)), rig)  # drives without :02..:04
    m, p = _preflight(act, rig.plan, pair)
    assert m.preflight_done
    ident = Identity.of(1, m.preflight.identities[1])
    assert (ident.vendor_id, ident.product_code, ident.revision, ident.serial) == (0xE3A, None, None, None)
    assert ident.as_json() == {"node": 1, "vendor_id": 0xE3A, "product_code": None, "revision": None, "serial": None}
    said = [e.what for e in m.drain_events() if getattr(e, "what", "").startswith("identity 0x1018:02")]
    assert said[0] == ("identity 0x1018:02 (product code: SDO abort 0x06090011, sub-index does not exist); 0x1018:03 "
                       "(revision: SDO abort 0x06090011, sub-index does not exist) not read: not compared with the "
                       "profile's canopen.product_code / revision_min")


def test_the_report_says_which_identity_was_not_read():
    from hil.report.shell import trace_lines

    html = trace_lines({"identity": {"ema1": {"node": 1, "vendor_id": 0xE3A, "product_code": None, "revision": None,
                                               "serial": None}}})
    assert "vendor 0x00000E3A, product not read, revision not read, serial" in html


def test_a_vendor_eds_listing_only_the_vendor_id_is_not_refused_and_the_drive_is_asked(tmp_path, simrig):
    """maxon's EPOS4 file with 0x1018:02..04 taken out (as other vendors ship theirs), the example profile written
    from docs/drives.md: planned without a refusal; its drives (simulated from that file) are asked by SDO."""
    import numpy as np
    from test_drive_examples import EXAMPLES, _eds

    from hil.profile.load import load_actuation
    from hil.profile.rig import plan_for
    from sim.plant import RigPlant
    from support.canopen_rig import make_pair
    from support.eds import write_eds_variant

    eds = write_eds_variant(tmp_path / "maxon_EPOS4.eds", source=_eds("maxon_EPOS4.eds"),
                            remove_subs=[(0x1018, 2), (0x1018, 3), (0x1018, 4)])
    path = EXAMPLES / "maxon_epos4.toml"
    act = load_actuation(path)
    rig = plan_for(act, path, eds)
    assert not rig.plan.node("ema1").can_read(0x1018, 2)
    m, p = _preflight(act, rig.plan, make_pair(RigPlant(simrig.params, np.random.default_rng(7)), rig))
    assert m.preflight_done and (0x1018, 2) in p.sdo_reads(1) and (0x1018, 4) in p.sdo_reads(2)
    assert m.preflight.identities[1]["vendor_id"] == act.canopen.vendor_id == 0xFB


def test_the_identity_read_before_a_failing_read_is_recorded(simrig):
    """0x1018:02 answered with an SDO abort (the EDS lists it: the preflight stops): what was read before
    (0x1018:01) is in the preflight record, the rest null."""
    import numpy as np

    from hil.canopen.frame import Frame
    from hil.canopen.sdo import SdoAbortError
    from hil.master.link import CanopenLink
    from hil.record.runrecord import Identity
    from hil.transport import InProcessTransport
    from sim.plant import RigPlant
    from support.canopen_rig import make_master, make_pair

    pair = make_pair(RigPlant(simrig.params, np.random.default_rng(8)))
    node = pair.nodes[0]
    serve = node.on_sdo

    def refuse_product_code(frame, t):
        if frame.data[0] == 0x40 and bytes(frame.data[1:4]) == b"\x18\x10\x02":
            node.outbox.append(Frame(0x581, b"\x80\x18\x10\x02" + (0x08000020).to_bytes(4, "little")))
            return None
        return serve(frame, t)

    node.on_sdo = refuse_product_code
    tr = InProcessTransport(pair, 0.002)
    link = CanopenLink(make_master(), tr)
    try:
        with pytest.raises(SdoAbortError, match=r"0x1018:02"):
            link.first_sample()
        link.close()
    finally:
        tr.close()
    got = link.preflight_record()["identity"]
    assert got == {"ema1": {"node": 1, "vendor_id": 0xE3A}, "ema2": None}
    assert Identity.of(1, {k: v for k, v in got["ema1"].items() if k != "node"}).as_json() == {
        "node": 1, "vendor_id": 0xE3A, "product_code": None, "revision": None}
    rec = RunRecord().with_preflight(link.preflight_record())  # as the run's record takes it when it stops
    assert rec.identity["ema1"].vendor_id == 0xE3A and rec.identity["ema2"] is None
    assert rec.process_image is None and rec.master_loss == {}
