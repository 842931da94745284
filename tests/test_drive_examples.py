"""The example profiles (profiles/examples/) on the vendors' EDS files, and the simulated drive on any EDS.

* The examples whose drives can do the check (maxon EPOS4 with the sensors on its analog inputs; Nanotec
  CL4-E with the sensors on a CiA 401 node) run the whole dry-run on simulated nodes built from the
  vendor's EDS: backlash within 0.005 mm of the simulator's truth on all three channels, LVDT pitch
  within 0.1 %, as the shipped profile (tests/test_dry_run.py).
* The examples that cannot (Technosoft iPOS, SCHUNK PRL 120) are refused by the plan with the problems
  their header comments quote, each naming its profile key and object.
* Every object of every vendor EDS is served by the simulated drive: read by SDO (a value in its data
  type; the EDS's default where it gives one), written back where writable.

The vendor files are read from ../shared/data/vendor-eds (never copied into the project); the tests
skip with the reason where that folder is absent.
"""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path

import canopen.objectdictionary as cod
import pytest

from blf.signals import CHANNELS
from hil.canopen.frame import Frame
from hil.canopen.od import load_eds
from hil.canopen.plan import PlanError
from hil.canopen.process import DriveMode
from hil.canopen.sdo import SdoAbortCode, SdoAbortError
from hil.canopen.signalmap import DeviceProfile, ForceControl, NodeRole, NodeSpec
from hil.profile.load import default_profile_path, load_actuation, load_check, load_simrig
from hil.profile.rig import plan_for
from hil.record.runfolder import read_record
from sim.drives import SimDrive
from sim.drives.served import own_data
from sim.drives.stats import PairCounters
from support.sim_bus import Bus

VENDOR = Path(__file__).resolve().parents[2] / "shared" / "data" / "vendor-eds"
EXAMPLES = default_profile_path("examples")
_absent = pytest.mark.skipif(not VENDOR.is_dir(), reason=f"vendor EDS files not present at {VENDOR} (../shared/data)")

#: example profile -> the vendor's EDS file it names
RUNNABLE = {"maxon_epos4.toml": "maxon_EPOS4.eds", "nanotec_cl4e_cia401.toml": "Nanotec_CL4-E-1-12.eds"}
REFUSED = {"technosoft_ipos.toml": "Technosoft_iPOS.eds", "schunk_prl120.toml": "Schunk_PRL120.eds"}


def _eds(name: str) -> Path:
    p = VENDOR / name
    if not p.is_file():
        pytest.skip(f"{name} not present at {VENDOR} (../shared/data/vendor-eds)")
    return p


def test_every_example_names_its_eds_as_the_vendor_ships_it():
    for profile, eds in {**RUNNABLE, **REFUSED}.items():
        act = load_actuation(EXAMPLES / profile)
        assert act.canopen.eds == eds, profile
        assert not (EXAMPLES / eds).exists()  # never copied into the project


# ------------------------------------------------------------------ the dry-runs


@_absent
@pytest.mark.slow
@pytest.mark.parametrize("profile", sorted(RUNNABLE))
def test_example_dry_run_recovers_the_truth(tmp_path, profile):
    from hil.cli.dry_run import dry_run

    path = EXAMPLES / profile
    act = load_actuation(path)
    r = dry_run(act, load_check(None, act), load_simrig(), tmp_path / "run", profile_path=path,
                eds=_eds(RUNNABLE[profile]))
    assert r.exit_code == 0
    res = json.loads((r.out / "result.json").read_text())
    meta = read_record(r.out)
    assert meta.status == "done" and res["status"] == "pass"
    assert {ch: res["verdict"][ch]["status"] for ch in CHANNELS} == {ch: "pass" for ch in CHANNELS}
    truth = res["truth"]
    for ch in CHANNELS:
        assert abs(res["backlash_mm"][ch] - truth["backlash_mm"][ch]) < 0.005, ch
    for k in ("ema1", "ema2"):
        assert res["calibration"][k]["pitch"] == pytest.approx(truth["calibration"][k]["pitch"], rel=1e-3)
    assert meta.can.missing_cycles == 0 and meta.can.bad_frames == 0
    pair = r.injector.pair
    assert len(pair.sensors) == (1 if "cia401" in profile else 0)


# ------------------------------------------------------------------ the refused examples


@_absent
@pytest.mark.parametrize("profile", sorted(REFUSED))
def test_example_that_cannot_do_the_check_is_refused_naming_key_and_object(profile):
    path = EXAMPLES / profile
    with pytest.raises(PlanError) as exc:
        plan_for(load_actuation(path), path, _eds(REFUSED[profile]))
    got = {(p.key, p.obj) for p in exc.value.problems}
    # a problem both drives share (one EDS) is said once, "at ema1, ema2"
    want = {("canopen.eds", "0x6502:00 (supported drive modes) at ema1, ema2")}
    if profile.startswith("technosoft"):
        want.add(("canopen.external_watchdog", "0x1016:01 (consumer heartbeat time) at ema1, ema2"))
    else:
        want |= {(f"signals.ema{ema}.target_position", f"0x607A:00 at ema{ema}") for ema in (1, 2)}
        want.add(("canopen.external_watchdog", "0x6007:00 (abort connection option code) at ema1, ema2"))
    assert got == want
    text = (path).read_text()
    for p in exc.value.problems:  # the header comment quotes every problem (emaN for one drive or both)
        for part in (p.key, p.obj):
            assert part.replace("ema1, ema2", "emaN").replace("ema1", "emaN").replace("ema2", "emaN") in text, part


# ------------------------------------------------------------------ any EDS, served


def _drive(od: cod.ObjectDictionary, node_id: int = 1, *, own: bool = True) -> tuple[SimDrive, Bus]:
    """A simulated drive on ``od`` alone (no plant: the sample stays the rig at rest), booted; with the
    own data a pair gives it (identity of the EDS's [DeviceInfo], CSP and CST) unless ``own`` is False."""
    info = od.device_information
    spec = NodeSpec("ema1", NodeRole.DRIVE, node_id, "x", info.vendor_number or 0, info.product_number or 0,
                    info.revision_number or 0, DeviceProfile.DRIVE, 0.1, "canopen")
    out: list[Frame] = []
    drive = SimDrive(node_id, 0, od, gear_ratio_rad_per_mm=5.0, counts_per_rev=None, sample_period_s=0.002,
                     counters=PairCounters(), outbox=out, motor_inertia_kg_m2=1e-4,
                     own_data=own_data(od, spec, ForceControl.CST) if own else None)

    class _One:
        def on_frame(self, frame: Frame, t: float) -> list[Frame]:
            if frame.arbitration_id == drive.sdo_request_cob_id:
                drive.on_sdo(frame, t)
            elif frame.arbitration_id == 0:
                drive.on_nmt_command(frame.data[0], t)
            got = out.copy()
            out.clear()
            return got

    drive.boot(0.0, communication_only=False)
    out.clear()
    return drive, Bus(_One())


def _variables(od: cod.ObjectDictionary):
    for index in od:
        obj = od[index]
        subs = [(0, obj)] if isinstance(obj, cod.ODVariable) else sorted(obj.subindices.items())
        for sub, var in subs:
            yield index, sub, var


@_absent
@pytest.mark.parametrize("eds", ["maxon_EPOS4.eds", "Nanotec_CL4-E-1-12.eds", "Technosoft_iPOS.eds",
                                 "Schunk_PRL120.eds"])
def test_every_object_of_a_vendor_eds_is_served(eds):
    """Objects without a default, DOMAIN and strings, records with gaps, $NODEID formulas, INTEGER32
    0x608F: every readable object reads by SDO as its EDS default (or its type's zero), every
    writable number takes its value back; reset node restores the defaults."""
    od = load_eds(_eds(eds), node_id=5)
    drive, bus = _drive(od, 5)
    n_read = n_written = 0
    for index, sub, var in _variables(od):
        if not var.readable:
            continue
        try:
            data = bus.sdo(5, index, sub)
        except SdoAbortError as exc:  # a string or domain the EDS leaves empty: no data available
            assert var.data_type not in cod.NUMBER_TYPES and exc.code == 0x08000024, (hex(index), sub)
            assert not var.default, (hex(index), sub)
            continue
        n_read += 1
        if var.data_type in cod.NUMBER_TYPES:
            assert len(data) == len(var) // 8, (hex(index), sub)
            value = var.decode_raw(data)
            live = (index, sub) in drive.store.live
            if var.default is not None and not live and (index, sub) not in drive.own_data:
                assert value == var.default or (isinstance(value, float) and math.isclose(value, var.default)), \
                    (hex(index), sub, value, var.default)
            if var.writable and not live:
                try:
                    bus.sdo(5, index, sub, data)  # its own value back: accepted or refused by the drive's rules
                    n_written += 1
                except SdoAbortError as exc:
                    assert exc.code in (SdoAbortCode.VALUE_RANGE_EXCEEDED, SdoAbortCode.VALUE_TOO_LOW,
                                        SdoAbortCode.WRITE_OF_READ_ONLY, SdoAbortCode.PARAMETER_INCOMPATIBILITY,
                                        SdoAbortCode.MAX_LESS_THAN_MIN), (hex(index), sub, exc.code)
    assert n_read > 100 and n_written > 20
    # $NODEID resolved for node 5 (every one of these files gives the EMCY and TPDO1 COB-IDs that way)
    assert bus.read(5, 0x1014, 0, "I") & 0x7FF == 0x85
    assert bus.read(5, 0x1800, 1, "I") & 0x7FF == 0x185
    assert bus.send(Frame(0x000, bytes([0x81, 5]))) == [Frame(0x705, b"\x00")]


@_absent
def test_vendor_quirks_served_as_the_eds_says():
    # EPOS4: no 0x608F, no 0x1006; quick stop option 6 (stay); TPDO COB-IDs with bit 30 (no RTR)
    od = load_eds(_eds("maxon_EPOS4.eds"), node_id=1)
    drive, bus = _drive(od)
    assert od.get(0x608F) is None and od.get(0x1006) is None
    assert bus.read(1, 0x605A, 0, "h") == 6
    assert bus.read(1, 0x1800, 1, "I") == 0x4000_0181
    bus.write(1, 0x1800, 1, "I", 0xC000_0181)  # disable, keeping bit 30: accepted
    bus.write(1, 0x1800, 1, "I", 0x4000_0181)
    assert drive.counts_per_rev == 4096  # neither 0x608F nor a profile: 4096 per revolution
    # Nanotec: 0x608F typed INTEGER32 without a default (the drive's own 4096), no 0x6076
    od = load_eds(_eds("Nanotec_CL4-E-1-12.eds"), node_id=1)
    drive, bus = _drive(od)
    assert od[0x608F][1].data_type == cod.INTEGER32 and od[0x608F][1].default is None
    assert od.get(0x6076) is None
    assert bus.read(1, 0x608F, 1, "i") == 4096  # the drive's own data, in its EDS type
    _, bare = _drive(od, own=False)
    assert bare.read(1, 0x608F, 1, "i") == 0  # without it: the type's zero
    spec = NodeSpec("ema1", NodeRole.DRIVE, 1, "x", 0x26C, 0x5A, 0, DeviceProfile.DRIVE, 0.1, "canopen")
    own = own_data(od, spec, counts_per_rev=8192)
    assert own[(0x608F, 1)] == struct.pack("<i", 8192)  # the profile's counts per revolution
    assert (0x6076, 0) not in own and (0x1018, 1) not in own  # no such object; the EDS gives the vendor


@_absent
def test_epos4_quick_stop_option_6_stays_until_disable_voltage():
    """As maxon ships it (0x605A = 6): quick stop active is kept after the stop, until disable voltage."""
    od = load_eds(_eds("maxon_EPOS4.eds"), node_id=1)
    drive, bus = _drive(od)
    bus.write(1, 0x6060, 0, "b", 8)
    for cw in (0x06, 0x07, 0x0F, 0x02):
        bus.write(1, 0x6040, 0, "H", cw)
    for _ in range(100):
        drive.drive_cycle()
    assert drive.state_machine.state.name == "QUICK_STOP_ACTIVE"
    assert drive.setpoint.mode is DriveMode.POSITION  # holding where the quick stop began
    bus.write(1, 0x6040, 0, "H", 0x00)
    assert bus.read(1, 0x6041, 0, "H") & 0x6F == 0x40  # switch on disabled
