"""The signal map and the rig plan: profile tables, every bad input named with its key before any frame,
``emacheck profile check``, the cycle codec, vendor EDS files nobody on the project wrote."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import pytest

from hil.canopen.cycle import CycleDecoder, SetpointEncoder, from_image, image_of
from hil.canopen.frame import Frame
from hil.canopen.pdo import PdoError, PdoLengthError
from hil.canopen.plan import PlanError
from hil.canopen.signalmap import ForceControl, Scale, ScaleSource, Signal, parse_object
from hil.cli import main
from hil.errors import ProfileError
from hil.profile.load import actuation_from_snapshot, actuation_tables, load_actuation
from hil.profile.rig import plan_for
from support.canopen_rig import shipped_rig
from support.profiles import write_profile_variant

SHARED = Path(__file__).resolve().parents[2] / "shared"
VENDOR = SHARED / "data" / "vendor-eds"
needs_vendor = pytest.mark.skipif(not VENDOR.is_dir(), reason=f"{VENDOR} is absent: the vendor EDS files are "
                                                             "read from ../shared (never copied into the project)")
# both EMAs' LVDT and force read from the drive's own objects (a vendor EDS has no sensor objects of ours)
_LVDT_AND_FORCE_AT_6064_6077 = {k: {"lvdt": {"object": "0x6064:00"}, "force": {"object": "0x6077:00"}}
                                for k in ("ema1", "ema2")}


def _profile(tmp_path, name="actuation.toml", **variant) -> Path:
    return write_profile_variant("actuation.toml", tmp_path / name, **variant)


# ------------------------------------------------------------------ the shipped profile


def test_the_shipped_profile_maps_the_shipped_drive():
    act = load_actuation()
    e = act.signals.entry(1, Signal.LVDT)
    assert (e.node, e.object, e.scale, e.source) == ("ema1", (0x2100, 0), Scale(1000.0), ScaleSource.PROFILE)
    angle = act.signals.entry(2, Signal.MOTOR_ANGLE)
    assert angle.scale.units_per_si == pytest.approx(4096 / (2 * math.pi), rel=1e-15)
    assert act.signals.entry(2, Signal.TARGET_POSITION).scale == angle.scale
    assert act.signals.entry(1, Signal.TARGET_TORQUE).source is ScaleSource.RATED_TORQUE
    assert act.signals.force_control is ForceControl.AUTO
    assert [d.force_control for d in shipped_rig().plan.drives] == [ForceControl.CST, ForceControl.CST]


def test_the_snapshot_of_a_profile_reads_back_as_the_same_profile():
    act = load_actuation()
    assert actuation_from_snapshot(json.loads(json.dumps(actuation_tables(act)))) == act


def test_a_snapshot_written_before_the_signal_map_reads_as_the_drive_of_then():
    snap = actuation_tables(load_actuation())
    del snap["signals"], snap["nodes"]
    snap["sensors"]["resolver_counts_per_rev"] = 8192
    act = actuation_from_snapshot(snap)
    assert act.signals.entry(1, Signal.MOTOR_ANGLE).scale.units_per_si == pytest.approx(8192 / (2 * math.pi))
    assert act.signals.entry(2, Signal.FORCE).object == (0x2101, 0)


@pytest.mark.parametrize("text,expected", [("0x6064:00", (0x6064, 0)), ("0x3160:01", (0x3160, 1)),
                                           ("3160sub1", (0x3160, 1)), ("0x6064", (0x6064, 0)),
                                           ("0x1A00:0A", (0x1A00, 10))])
def test_object_addresses(text, expected):
    assert parse_object(text, "k") == expected


@pytest.mark.parametrize("text", ["0x6064:100", "6064.1", "0x0FFF:00", 6064, "0x16064"])
def test_object_addresses_refused(text):
    with pytest.raises(ValueError, match=r"'signals.x.object' = .*(is not an object address|index must be 0x1000)"):
        parse_object(text, "signals.x.object")


# ------------------------------------------------------------------ the profile's tables, refused with their key


@pytest.mark.parametrize("variant,message", [
    (dict(remove=["signals"]), r"missing tables '\[signals.ema1\]' and '\[signals.ema2\]'"),
    (dict(remove=["signals.ema2.lvdt"]), r"missing field 'signals.ema2.lvdt' \(where the check reads EMA 2's lvdt"),
    (dict(overrides={"signals": {"ema1": {"lvdt": {"mm_per_unit": 0.0}}}}),
     r"field 'signals.ema1.lvdt.mm_per_unit' = 0: a scaling of zero"),
    (dict(overrides={"signals": {"ema2": {"force": {"N_per_unit": 0}}}}),
     r"field 'signals.ema2.force.N_per_unit' = 0: a scaling of zero"),
    (dict(overrides={"signals": {"ema1": {"lvdt": {"object": "0x2100.0"}}}}),
     r"field 'signals.ema1.lvdt.object' = '0x2100.0' is not an object address"),
    (dict(remove=["signals.ema1.motor_angle.counts_per_rev"]),
     r"'signals.ema1.motor_angle' needs exactly one of counts_per_rev"),
    (dict(add={"signals": {"ema1": {"lvdt": {"node": "io"}}}}), r"field 'signals.ema1.lvdt.node' = 'io' is not a node"),
    (dict(add={"signals": {"ema1": {"lvdt": {"type": "INTEGER23"}}}}),
     r"field 'signals.ema1.lvdt.type' = 'INTEGER23' is not a CiA 301 data type \(did you mean 'INTEGER32'\?\)"),
    (dict(add={"signals": {"ema1": {"lvdt_mm": {"object": "0x2100:00"}}}}), r"unknown field 'signals.ema1.lvdt_mm'"),
    (dict(add={"signals": {"ema1": {"lvdt": {"mm_per_volt": 1.0}}}}), r"unknown field 'signals.ema1.lvdt.mm_per_volt'"),
    (dict(overrides={"canopen": {"force_control": "torque"}}), r"field 'canopen.force_control' = 'torque'"),
    (dict(overrides={"canopen": {"gear_ratio_object": "gear"}}), r"field 'canopen.gear_ratio_object' = 'gear'"),
    (dict(add={"canopen": {"cob_ids": {"ema3.TPDO1": 0x190}}}), r"field 'canopen.cob_ids.ema3.TPDO1': a key is"),
    (dict(add={"canopen": {"cob_ids": {"ema1.TPDO1": 0x800}}}), r"field 'canopen.cob_ids.ema1.TPDO1' = 2048"),
    (dict(add={"nodes": {"io": {"node_id": 2, "eds": "cia401_io.eds", "vendor_id": 1, "product_code": 1,
                                "revision_min": 0}}}),
     r"fields 'nodes.io.node_id' and 'canopen.node_id_ema2' are both 2"),
    (dict(add={"nodes": {"io": {"node_id": 3, "eds": "cia401_io.eds", "vendor_id": 1, "product_code": 1,
                                "revision_min": 0, "device_profile": 402}}}),
     r"field 'nodes.io.device_profile' = 402: a sensor node is a CiA 401"),
    (dict(add={"nodes": {"EMA3": {"node_id": 3}}}), r"table 'nodes.EMA3': a node name is lower-case"),
    (dict(add={"sensors": {"resolver_counts_per_rev": 4096}}),
     r"field 'sensors.resolver_counts_per_rev' has moved to 'signals.ema1.motor_angle.counts_per_rev"),
])
def test_signal_map_errors_name_the_field(tmp_path, variant, message):
    with pytest.raises(ProfileError, match=r"actuation.toml: .*" + message):
        load_actuation(_profile(tmp_path, **variant))


def _problems(tmp_path, **variant) -> list[str]:
    prof = _profile(tmp_path, **variant)
    with pytest.raises(PlanError) as exc:
        plan_for(load_actuation(prof), prof)
    return [str(p) for p in exc.value.problems]


@pytest.mark.parametrize("variant,problem", [
    (dict(overrides={"signals": {"ema1": {"lvdt": {"object": "0x2199:00"}}}}),
     "signals.ema1.lvdt: 0x2199:00 at ema1: no such object in ema_drive.eds"),
    (dict(overrides={"signals": {"ema1": {"force": {"object": "0x1017:00"}}}}),
     "signals.ema1.force: 0x1017:00 at ema1: is not PDO-mappable in ema_drive.eds"),
    (dict(add={"canopen": {"cob_ids": {"ema1.TPDO2": 0x282}}}),
     "canopen.cob_ids: ema2.TPDO2: COB-ID 0x282 is also ema1.TPDO2's: two PDOs overlap"),
    (dict(add={"canopen": {"cob_ids": {"ema1.TPDO1": 0x77F}}}),
     "canopen.cob_ids: ema1.TPDO1: COB-ID 0x77F is the the master's heartbeat"),
    (dict(add={"canopen": {"cob_ids": {"ema2.RPDO1": 0x082}}}),
     "canopen.cob_ids: ema2.RPDO1: COB-ID 0x082 is the EMCY of node 2 (EMA 2)"),
    (dict(overrides={"canopen": {"bitrate_bps": 250000}}),
     "canopen.bitrate_bps: the PDO layout loads the bus to 170.0% in the worst case at 250000 bit/s"),
    (dict(overrides={"canopen": {"force_control": "cst", "eds": "cia401_io.eds"}}),
     "canopen.eds: 0x1000:00 (device type) at ema1, ema2: cia401_io.eds says device profile 401 (0x00040191), "
     "the profile expects 402"),
])
def test_a_map_that_does_not_fit_its_eds_names_key_and_object(tmp_path, variant, problem):
    got = _problems(tmp_path, **variant)
    assert any(p.startswith(problem) for p in got), got


def test_a_stated_type_overrides_the_eds_and_says_so(tmp_path):
    """docs/drives.md: ``type`` states what the drive sends where its EDS is wrong; the PDO mapping and
    the SDO codec follow the profile, and the plan's notes say that the EDS was overridden."""
    prof = _profile(tmp_path, add={"signals": {"ema2": {"force": {"type": "INTEGER16"}}}})
    rig = plan_for(load_actuation(prof), prof)
    ch = rig.plan.channel(2, Signal.FORCE)
    assert ch.data_type == 0x0003 and rig.plan.channel(1, Signal.FORCE).data_type == 0x0004
    assert rig.plan.node("ema2").types[(0x2101, 0)] == 0x0003 and rig.plan.node("ema1").types[(0x2101, 0)] == 0x0004
    mapped = [o for p in rig.plan.node("ema2").layout.pdos for o in p.entries if (o.index, o.subindex) == (0x2101, 0)]
    assert [o.data_type for o in mapped] == [0x0003]
    assert ("signals.ema2.force.type = 0x0003 (INTEGER16) overrides ema_drive.eds's 0x0004 (INTEGER32) for "
            "0x2101:00 at ema2: the drive is taken to send what the profile states") in rig.plan.notes
    # stating the EDS's own type changes nothing and notes nothing
    prof = _profile(tmp_path, add={"signals": {"ema2": {"force": {"type": "INTEGER32"}}}})
    rig = plan_for(load_actuation(prof), prof)
    assert rig.plan.channel(2, Signal.FORCE).data_type == 0x0004 and not any("overrides" in n for n in rig.plan.notes)


def test_every_problem_is_reported_not_only_the_first(tmp_path):
    got = _problems(tmp_path, overrides={"signals": {"ema1": {"lvdt": {"object": "0x2199:00"}},
                                                     "ema2": {"force": {"object": "0x1017:00"}}},
                                         "canopen": {"bitrate_bps": 125000}})
    assert [p.split(":")[0] for p in got] == ["signals.ema1.lvdt", "signals.ema2.force", "canopen.bitrate_bps"]


# ------------------------------------------------------------------ emacheck profile check


def test_profile_check_of_the_shipped_profile(capsys):
    from hil.profile.load import default_profile_path

    assert main(["profile", "check", str(default_profile_path("actuation.toml"))]) == 0
    out = capsys.readouterr().out
    assert "profile OK" in out and "42.5% worst case" in out and "0x281" in out
    assert main(["profile", "check", str(default_profile_path("actuation.toml")), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["ok"] and data["bus_load"]["worst"] == pytest.approx(0.4251)
    assert [(r["node"], r["pdo"], r["cob_id"]) for r in data["pdos"]][:4] == [
        ("ema1", "RPDO1", "0x201"), ("ema1", "RPDO2", "0x301"), ("ema1", "TPDO1", "0x181"), ("ema1", "TPDO2", "0x281")]
    assert data["force_control"] == {"ema1": "cst", "ema2": "cst"}


def test_profile_check_lists_every_problem_and_exits_3(tmp_path, capsys):
    prof = _profile(tmp_path, overrides={"signals": {"ema1": {"lvdt": {"object": "0x2199:00"}}}},
                    add={"canopen": {"cob_ids": {"ema1.TPDO2": 0x282}}})
    assert main(["profile", "check", str(prof)]) == 3
    out = capsys.readouterr().out
    assert "2 problem(s); nothing was sent on any bus" in out
    assert "signals.ema1.lvdt 0x2199:00 at ema1: no such object in ema_drive.eds" in out
    assert "canopen.cob_ids ema2.TPDO2: COB-ID 0x282 is also ema1.TPDO2's" in out
    assert main(["profile", "check", str(prof), "--json"]) == 3
    data = json.loads(capsys.readouterr().out)
    assert not data["ok"] and [p["key"] for p in data["problems"]] == ["signals.ema1.lvdt", "canopen.cob_ids"]


@pytest.mark.parametrize("command", [["dry-run", "--quiet"], ["run", "--interface", "virtual", "--channel",
                                                               "emacheck-test-plan", "--arm", "--quiet"]])
def test_run_and_dry_run_refuse_a_bad_map_before_any_frame(tmp_path, capsys, command):
    prof = _profile(tmp_path, overrides={"signals": {"ema2": {"force": {"object": "0x1017:00"}}}})
    out = tmp_path / "out"
    assert main([*command, "--profile", str(prof), "--out", str(out)]) == 3
    err = capsys.readouterr().err
    assert "signals.ema2.force: 0x1017:00 at ema2: is not PDO-mappable" in err
    assert not out.exists()  # no run folder: nothing ran, nothing was sent


def test_eds_given_on_the_command_line_replaces_the_profiles(tmp_path, capsys):
    from hil.profile.load import default_profile_path

    prof = _profile(tmp_path, overrides={"canopen": {"eds": "vendor_drive.eds"}})
    assert main(["profile", "check", str(prof)]) == 3
    # the profile's file is named (found by the readers' fuzzing: a mutated EDS name gave exit 3 naming no file)
    assert f"actuation profile {prof}: field 'canopen.eds' = 'vendor_drive.eds': no such EDS" in capsys.readouterr().err
    assert main(["profile", "check", str(prof), "--eds", str(default_profile_path("ema_drive.eds"))]) == 0
    assert main(["profile", "check", str(prof), "--eds", str(tmp_path / "nope.eds")]) == 3
    assert "--eds" in capsys.readouterr().err


# ------------------------------------------------------------------ vendor EDS files nobody on the project wrote


def _vendor_profile(tmp_path, eds: str, ident: tuple[int, int, int], add=None, **over) -> Path:
    canopen = {"eds": str(VENDOR / eds), "vendor_id": ident[0], "product_code": ident[1], "revision_min": ident[2],
               "gear_ratio_object": ""}
    canopen.update(over.pop("canopen", {}))
    return _profile(tmp_path, overrides={"canopen": canopen, **over}, add=add or {})


@needs_vendor
def test_technosoft_ipos_cannot_do_the_check_and_profile_check_says_why(tmp_path):
    got = _problems(tmp_path, overrides={"canopen": {"eds": str(VENDOR / "Technosoft_iPOS.eds"), "vendor_id": 0x1A3,
                                                     "product_code": 0, "revision_min": 0},
                                         "signals": _LVDT_AND_FORCE_AT_6064_6077})
    assert any(p.startswith("canopen.eds: 0x6502:00 (supported drive modes) at ema1, ema2: Technosoft_iPOS.eds "
                            "announces neither CSP nor CST") for p in got), got
    assert any(p.startswith("canopen.external_watchdog: 0x1016:01 (consumer heartbeat time) at ema1, ema2: not in "
                            "Technosoft_iPOS.eds") for p in got), got


@needs_vendor
def test_schunk_prl120_cannot_do_the_check_and_profile_check_says_why(tmp_path):
    got = _problems(tmp_path, overrides={"canopen": {"eds": str(VENDOR / "Schunk_PRL120.eds"), "vendor_id": 0,
                                                     "product_code": 0, "revision_min": 0},
                                         "signals": _LVDT_AND_FORCE_AT_6064_6077})
    for start in ("canopen.eds: 0x6502:00 (supported drive modes) at ema1, ema2: Schunk_PRL120.eds announces neither",
                  "signals.ema1.target_position: 0x607A:00 at ema1: is not PDO-mappable in Schunk_PRL120.eds",
                  "canopen.external_watchdog: 0x6007:00 (abort connection option code) at ema1, ema2: not in"):
        assert any(p.startswith(start) for p in got), (start, got)


@needs_vendor
def test_nanotec_without_rated_torque_falls_back_to_csp_or_takes_the_profiles(tmp_path):
    ident = (0x26C, 0x5A, 0x8A50000)
    nano = {"signals": {k: {"lvdt": {"object": "0x3320:01", "mm_per_unit": 0.001},
                            "force": {"object": "0x3320:01", "N_per_unit": 0.1}} for k in ("ema1", "ema2")}}
    plan = plan_for(load_actuation(p := _vendor_profile(tmp_path, "Nanotec_CL4-E-1-12.eds", ident, **nano)), p).plan
    assert [d.force_control for d in plan.drives] == [ForceControl.CSP, ForceControl.CSP]
    assert any("no CST: 0x6076 (motor rated torque) is not in Nanotec_CL4-E-1-12.eds" in n for n in plan.notes)
    rated = {"signals": {k: {"target_torque": {"rated_torque_Nm": 0.5}} for k in ("ema1", "ema2")}}
    plan = plan_for(load_actuation(p := _vendor_profile(tmp_path, "Nanotec_CL4-E-1-12.eds", ident, add=rated,
                                                        **nano)), p).plan
    assert [d.force_control for d in plan.drives] == [ForceControl.CST, ForceControl.CST]
    # its four TPDOs and RPDOs are enabled by the EDS: those the check does not use are disabled
    assert len(plan.node("ema1").layout.disable) >= 2


# ------------------------------------------------------------------ the cycle codec


def test_the_decoder_forms_the_sample_once_every_input_pdo_arrived():
    plan = shipped_rig().plan
    dec = CycleDecoder(plan.tx_pdos, [c for c in plan.channels if c.signal.direction.value == "tx"])
    assert dec.cob_ids == {0x181, 0x182, 0x281, 0x282}
    dec.reset()
    assert dec.feed(plan.node("ema1").layout["TPDO1"].pack((0x0237, 4096, 8))) == (1,)
    assert dec.feed(plan.node("ema2").layout["TPDO1"].pack((0x0237, -2048, 8))) == (2,)
    assert dec.feed(plan.node("ema1").layout["TPDO2"].pack((12345, -60000))) == ()
    assert not dec.complete and dec.missing() == [0x282]
    assert dec.feed(Frame(0x123, b"")) is None
    dec.feed(plan.node("ema2").layout["TPDO2"].pack((-1, 7)))
    assert dec.complete
    s = dec.sample(0.004)
    assert (s.t_s, s.s1_mm, s.s2_mm, s.F1_N, s.F2_N) == (0.004, 12.345, -0.001, -6000.0, 0.7)
    assert s.phi1_rad == pytest.approx(2 * math.pi, rel=1e-15) and s.phi2_rad == pytest.approx(-math.pi, rel=1e-15)
    assert dec.statusword == [0x0237, 0x0237] and dec.mode_display == [8, 8]
    f = plan.node("ema1").layout["TPDO2"].pack((12345, -60000))
    assert dec.scaled(f) == {(1, Signal.LVDT): 12.345, (1, Signal.FORCE): -6000.0}
    assert plan.node("ema1").layout["TPDO2"].unpack(dec.rescaled(f, {(1, Signal.LVDT): 14.0})) == (14000, -60000)


def test_the_setpoint_encoder_and_its_inverse():
    plan = shipped_rig().plan
    # the target torque at a rated torque of 1 N m, as the drive's 0x6076 = 1000 says in the preflight
    rx = [dataclasses.replace(c, scale=Scale(1.0 / 5.026548245743669)) if c.signal is Signal.TARGET_TORQUE else c
          for c in plan.channels if c.signal.direction.value == "rx"]
    enc = SetpointEncoder(plan.rx_pdos, rx)
    (f,) = enc.frames(2, 0x000F, 2 * math.pi, 0.0)
    assert f == Frame(0x202, bytes.fromhex("0F 00 00 10 00 00 00 00"))
    (f,) = enc.frames(1, 0x000F, 0.0, 10_000.0)  # 10 kN at 1 N m rated: 1989.4 per mille
    assert f.data[-2:] == (1989).to_bytes(2, "little", signed=True)
    (f,) = enc.frames(1, 0x000F, 0.0, 1e9)
    assert f.data[-2:] == (32767).to_bytes(2, "little", signed=True)  # clipped to INTEGER16
    assert enc.mode_frame(1, 10) == Frame(0x301, b"\x0a") and enc.has_mode_pdo(2)
    back = enc.decode(Frame(0x202, bytes.fromhex("0F 00 00 10 00 00 C5 07")))
    assert (back.ema, back.controlword, back.mode) == (2, 0x000F, None)
    assert back.target_position_rad == pytest.approx(2 * math.pi)
    assert back.target_torque_N == pytest.approx(1989 * 5.026548245743669)
    assert enc.decode(Frame(0x302, b"\x08")).mode == 8 and enc.decode(Frame(0x181, b"")) is None
    (f,) = enc.frames(1, 0x000F, -1e12, -1e9)  # both clipped to their types' lower ends
    assert f == Frame(0x201, bytes.fromhex("0F 00 00 00 00 80 00 80"))
    with pytest.raises(PdoError, match=r"^RPDO1 COB-ID 0x201: cannot encode \(65536, 0, 0\)"):
        enc.frames(1, 0x10000, 0.0, 0.0)  # a controlword is not clipped: refused, naming the PDO


def test_the_decoder_refuses_a_tpdo_of_another_length_naming_it():
    plan = shipped_rig().plan
    dec = CycleDecoder(plan.tx_pdos, [c for c in plan.channels if c.signal.direction.value == "tx"])
    dec.reset()
    for n in (0, 6, 8):
        with pytest.raises(PdoLengthError, match=f"^TPDO1 COB-ID 0x182: expected 7 data bytes, got {n}$"):
            dec.feed(Frame(0x182, bytes(n)))
    assert dec.missing() == [0x181, 0x182, 0x281, 0x282] and dec.statusword == [None, None]


def test_the_process_image_reads_back_as_the_same_codec():
    plan = shipped_rig().plan
    pdos, chans = from_image(json.loads(json.dumps(image_of(plan.tx_pdos + plan.rx_pdos, plan.channels))))
    assert pdos == plan.tx_pdos + plan.rx_pdos and chans == plan.channels
