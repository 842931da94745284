"""The shipped EDS files: load, pass the plan, identity and PDO defaults; broken ones refused naming key and object."""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
import sysconfig
from pathlib import Path

import pytest
from canopen.objectdictionary import ODRecord

from hil.canopen.errors import CanopenInputError, EdsError
from hil.canopen.od import (
    AbortConnectionOption,
    decode_value,
    default_eds_path,
    encode_value,
    load_eds,
    lookup,
    master_loss_steps,
    od_variable,
    type_name,
)
from hil.canopen.plan import PlanError
from hil.profile.load import default_profile_path, load_actuation
from hil.profile.rig import plan_for
from support.canopen_rig import shipped_rig
from support.ci import skip_or_fail
from support.profiles import write_profile_variant


@pytest.fixture(scope="module")
def od():
    return load_eds(node_id=2)


def default(od, index, sub=0):
    return od_variable(od, index, sub).default


def test_shipped_eds_loads_and_passes_the_plan(od):
    assert shipped_rig().plan.nodes[0].eds == "ema_drive.eds"
    load_eds()  # without node id ($NODEID defaults unresolved) too
    info = od.device_information
    assert (info.vendor_name, info.product_name) == ("emacheck", "EMA drive (simulated)")
    assert (info.vendor_number, info.product_number, info.revision_number) == (0x0E3A, 0x0402, 0x00010000)
    assert 1_000_000 in info.allowed_baudrates
    assert (info.nr_of_RXPDO, info.nr_of_TXPDO) == (2, 2)
    assert default_eds_path().name == "ema_drive.eds"


def test_identity_and_device_defaults(od):
    assert default(od, 0x1000) == 0x00020192  # CiA 402 servo drive
    assert isinstance(od[0x1018], ODRecord)
    assert [default(od, 0x1018, s) for s in (1, 2, 3, 4)] == [0x00000E3A, 0x00000402, 0x00010000, 0]
    assert default(od, 0x1008) == "EMA drive"
    assert default(od, 0x1014) == 0x82  # $NODEID + 0x80
    assert default(od, 0x6076) == 1000  # mNm
    assert (default(od, 0x608F, 1), default(od, 0x608F, 2)) == (4096, 1)
    assert (default(od, 0x60C2, 1), default(od, 0x60C2, 2)) == (2, -3)  # 2 ms
    assert default(od, 0x6502) == (1 << 7) | (1 << 9)  # CSP and CST
    assert default(od, 0x605A) == 2
    assert (default(od, 0x607D, 1), default(od, 0x607D, 2)) == (-65536, 65536)  # +-20 mm
    assert default(od, 0x2102) == pytest.approx(2 * 3.141592653589793 * 4 / 5, rel=1e-7)


def test_pdo_defaults_equal_the_layout(od):
    for p in shipped_rig().plan.node("ema2").layout.pdos:
        assert default(od, p.comm_index, 1) == p.cob_id, p.name
        assert default(od, p.comm_index, 2) == p.transmission_type, p.name
        assert default(od, p.mapping_index, 0) == len(p.entries), p.name
        got = [default(od, p.mapping_index, k) for k in range(1, 9)]
        assert got == [e.mapping_entry for e in p.entries] + [0] * (8 - len(p.entries)), p.name
    assert od_variable(load_eds(), 0x1800, 1).default_raw == "$NODEID+0x180"


def test_value_codec(od):
    assert encode_value(od, 0x1017, 0, 100) == b"\x64\x00"
    assert encode_value(od, 0x60C2, 2, -3) == b"\xfd"
    assert decode_value(od, 0x2102, 0, struct.pack("<f", 5.0265482)) == pytest.approx(5.0265482, rel=1e-7)
    assert decode_value(od, 0x1008, 0, b"EMA drive\x00") == "EMA drive"
    with pytest.raises(EdsError, match="cannot encode 70000"):
        encode_value(od, 0x1017, 0, 70000)
    with pytest.raises(EdsError, match="0x1016:05 is not in the object dictionary"):
        od_variable(od, 0x1016, 5)  # canopen would synthesise array members; we do not


def _sections(text: str) -> list[list[str]]:
    """The EDS as blocks of lines, one block per section (split at blank lines)."""
    return [block.split("\n") for block in text.strip("\n").split("\n\n")]


def _broken(tmp_path: Path, section: str, key: str | None = None, value: str = "") -> Path:
    """The shipped EDS with ``[section]`` removed (key None) or its ``key`` set to ``value``."""
    blocks = _sections(default_eds_path().read_text())
    hits = [b for b in blocks if b[0] == f"[{section}]"]
    assert len(hits) == 1, section
    if key is None:
        blocks.remove(hits[0])
    else:
        lines = hits[0]
        k = next(i for i, line in enumerate(lines) if line.startswith(key + "="))
        lines[k] = f"{key}={value}"
    p = tmp_path / "broken.eds"
    p.write_text("\n\n".join("\n".join(b) for b in blocks) + "\n")
    return p


def _plan(tmp_path, eds: Path):
    prof = write_profile_variant("actuation.toml", tmp_path / "actuation.toml", {"canopen": {"eds": str(eds)}})
    return plan_for(load_actuation(prof), prof)


@pytest.mark.parametrize("section,key,value,message", [
    ("6041", None, "", r"signals.ema1.statusword: 0x6041:00 at ema1: no such object in broken.eds"),
    ("1A01sub2", None, "", r"signals.ema1.force: 0x2101:00 at ema1: no TPDO left to carry it: broken.eds has 2 "
                           r"TPDO\(s\) the master may map and the map needs more"),
    ("6064", "DataType", "0x0003",
     r"signals.ema1.motor_angle: 0x6064:00 at ema1: data type 0x0003 \(INTEGER16\) "
     r".*CiA 402 says 0x0004 \(INTEGER32\)"),
    ("6040", "AccessType", "ro", r"signals.ema1.controlword: 0x6040:00 at ema1: is not writable in broken.eds "
                                 r"\(access ro\)"),
    ("2100", "PDOMapping", "0", r"signals.ema1.lvdt: 0x2100:00 at ema1: is not PDO-mappable in broken.eds"),
    ("1018sub1", None, "", r"canopen.eds: 0x1018:01 \(vendor-ID\) at ema1, ema2: not in broken.eds"),
    ("6007", None, "", r"canopen.external_watchdog: 0x6007:00 \(abort connection option code\) at ema1, ema2: not "
                       r"in broken.eds"),
    ("1016sub1", None, "", r"canopen.external_watchdog: 0x1016:01 \(consumer heartbeat time\) at ema1, ema2: not "
                           r"in broken.eds"),
    ("1016sub1", "AccessType", "ro", r"canopen.external_watchdog: 0x1016:01 \(consumer heartbeat time\) at ema1, "
                                     r"ema2: not writable in broken.eds \(access ro\)"),
    ("1017", "AccessType", "ro", r"canopen.eds: 0x1017:00 \(producer heartbeat time\) at ema1, ema2: not writable"),
])
def test_broken_eds_refused_with_key_and_object_named(tmp_path, section, key, value, message):
    path = _broken(tmp_path, section, key, value)
    with pytest.raises(PlanError, match=message) as exc:
        _plan(tmp_path, path)
    problems = [str(p) for p in exc.value.problems]
    assert all(p.startswith(("signals.", "canopen.")) for p in problems), problems


def test_unchanged_copy_passes(tmp_path):
    text = default_eds_path().read_text()
    assert "\n\n".join("\n".join(b) for b in _sections(text)) + "\n" == text
    _plan(tmp_path, _broken(tmp_path, "6041", "DefaultValue", "0x0000"))


def test_missing_or_garbage_eds(tmp_path):
    with pytest.raises(EdsError, match="EDS not found"):
        load_eds(tmp_path / "nope.eds")
    bad = tmp_path / "bad.eds"
    bad.write_text("[DeviceInfo]\nVendorName=x\n\n[6041]\nObjectType=0x7\n")  # no ParameterName
    with pytest.raises(EdsError, match="bad.eds: not a valid EDS"):
        load_eds(bad)


@pytest.mark.parametrize("exc, reason", [(PermissionError(13, "Permission denied"), "Permission denied"),
                                         (OSError("no strerror"), "no strerror")])
def test_an_eds_that_cannot_be_read_is_refused_with_the_systems_reason(tmp_path, monkeypatch, exc, reason):
    """A read error (as root no permission bit refuses a read, so the read is made to fail) names the file
    and the system's reason, else the error itself."""
    eds = tmp_path / "drive.eds"
    shutil.copy(default_eds_path(), eds)

    def fail(self):
        raise exc

    monkeypatch.setattr(Path, "read_bytes", fail)
    with pytest.raises(EdsError) as err:
        load_eds(eds)
    assert str(err.value) == f"{eds}: cannot read the EDS: {reason}"


def test_master_loss_objects_in_the_shipped_eds(od):
    """The drive's own reaction to the master's death: consumer heartbeat 0x1016 (four entries,
    all unused by default) and the CiA 402 abort connection option 0x6007 (default 1, fault)."""
    assert default(od, 0x1016, 0) == 4
    for k in range(1, 5):
        var = od_variable(od, 0x1016, k)
        assert (var.data_type, var.default, var.writable, var.readable) == (0x0007, 0, True, True), k
    var = od_variable(od, 0x6007, 0)
    assert (var.data_type, var.default, var.writable) == (0x0003, 1, True)
    assert [int(o) for o in AbortConnectionOption] == [0, 1, 2, 3]
    assert all(d.reaction for d in shipped_rig().plan.drives)
    steps = master_loss_steps(127, 125)
    assert [(st.index, st.subindex, st.data.hex(), st.write) for st in steps] == [
        (0x1016, 1, "7d007f00", True), (0x6007, 0, "0300", True)]
    for st in steps:  # each value as the EDS types it
        assert encode_value(od, st.index, st.subindex, decode_value(od, st.index, st.subindex, st.data)) == st.data


def test_eds_without_the_reaction_passes_only_where_the_rig_states_another(tmp_path):
    eds = _broken(tmp_path, "6007")
    with pytest.raises(PlanError, match=r"0x6007:00 \(abort connection option code\) at ema1, ema2: not in broken.eds"):
        _plan(tmp_path, eds)
    prof = write_profile_variant("actuation.toml", tmp_path / "wd.toml", {"canopen": {
        "eds": str(eds), "external_watchdog": "the rig's relay drops STO 100 ms after the master's last heartbeat"}})
    plan = plan_for(load_actuation(prof), prof).plan
    assert [d.reaction for d in plan.drives] == [False, False]


def _eds_validate() -> list[str]:
    """The command of eds-utils' ``eds-validate`` (the ``test`` extra installs it).

    pip puts a console script into the scripts directory of the interpreter that installed it (or of
    the user scheme for ``pip install --user``). That directory is on PATH only while its environment
    is active: an interpreter run by its path (a venv not activated, ``/path/to/python -m pytest``,
    pyenv's version directory without its shims) finds eds-utils importable and ``eds-validate`` not on
    PATH. So the script is looked for next to this interpreter first, then on PATH; where it is
    absent, the test skips (fails under CI=true).
    """
    for scheme in (None, f"{os.name}_user"):
        try:
            scripts = sysconfig.get_path("scripts") if scheme is None else sysconfig.get_path("scripts", scheme)
        except KeyError:
            continue
        exe = Path(scripts) / "eds-validate"
        if exe.is_file() and os.access(exe, os.X_OK):
            return [str(exe)]
    found = shutil.which("eds-validate")
    if found:
        return [found]
    skip_or_fail("eds-utils' eds-validate is installed neither next to this interpreter "
                 f"({sysconfig.get_path('scripts')}) nor on PATH (pip install eds-utils): the shipped EDS is "
                 "checked by canopen's parser only")


@pytest.mark.parametrize("name", ["ema_drive.eds", "cia401_io.eds"])
def test_shipped_eds_passes_eds_utils_validation(name):
    r = subprocess.run([*_eds_validate(), str(default_profile_path(name))], capture_output=True, text=True, timeout=60,
                       check=False)
    assert r.returncode == 0 and not r.stdout.strip(), r.stdout + r.stderr


def test_eds_utils_refuses_a_broken_eds(tmp_path):
    """The validation above can fail: an object with an invalid data type is refused."""
    bad = _broken(tmp_path, "6007", "DataType", "0x0099")
    r = subprocess.run([*_eds_validate(), str(bad)], capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode != 0 and "[6007]" in r.stdout + r.stderr


# --------------------------------------------------------------------------- pinned by mutation (issue 26)
# The EdsError messages name the object, the value or bytes and the data type word for word; the
# loader takes EDS and DCF in any case of the suffix and names a wrong one.


def test_type_names():
    assert type_name(0x0007) == "0x0007 (UNSIGNED32)"
    assert type_name(0x0003) == "0x0003 (INTEGER16)"
    assert type_name(0x0099) == "0x0099 (unknown)"
    assert type_name(None) == "none"


def test_codec_errors_word_for_word(od):
    with pytest.raises(EdsError) as exc:
        encode_value(od, 0x1017, 0, 70000)
    assert str(exc.value) == ("0x1017:00 (Producer heartbeat time): cannot encode 70000 as 0x0006 (UNSIGNED16): "
                              "Value does not fit in specified type")
    with pytest.raises(EdsError) as exc:
        decode_value(od, 0x1017, 0, b"\x01\x02\x03")
    assert str(exc.value) == ("0x1017:00 (Producer heartbeat time): cannot decode 010203 as 0x0006 (UNSIGNED16): "
                              "Mismatch between expected and actual data size")
    with pytest.raises(EdsError) as exc:
        decode_value(od, 0x6007, 0, bytearray(b"\x03"))
    assert str(exc.value).startswith("0x6007:00 (Abort connection option code): cannot decode 03 as "
                                     "0x0003 (INTEGER16): ")


def test_a_plain_variable_has_only_subindex_0(od):
    assert lookup(od, 0x1017, 0) is od[0x1017]
    assert lookup(od, 0x1017, 1) is None and lookup(od, 0x1017, 2) is None
    assert lookup(od, 0x1016, 1) is od[0x1016][1] and lookup(od, 0x1016, 5) is None
    assert lookup(od, 0x5FFF, 0) is None
    with pytest.raises(EdsError, match=r"^object 0x1017:01 is not in the object dictionary$"):
        od_variable(od, 0x1017, 1)


@pytest.mark.parametrize("name", ["drive.eds", "drive.EDS", "drive.dcf", "drive.DCF", "drive.Dcf"])
def test_eds_and_dcf_load_whatever_the_case_of_the_suffix(tmp_path, name):
    p = tmp_path / name
    shutil.copyfile(default_eds_path(), p)
    assert load_eds(p, node_id=3).device_information.product_name == "EMA drive (simulated)"


@pytest.mark.parametrize("name,suffix", [("drive.txt", "'.txt'"), ("drive", "''"), ("drive.eds.bak", "'.bak'"),
                                         ("drive.xdd", "'.xdd'")])
def test_other_suffixes_refused_naming_the_suffix(tmp_path, name, suffix):
    p = tmp_path / name
    shutil.copyfile(default_eds_path(), p)
    with pytest.raises(EdsError) as exc:
        load_eds(p)
    assert str(exc.value) == f"{p}: not an EDS/DCF file (suffix {suffix})"


def test_invalid_eds_error_names_the_file_and_the_parser_error(tmp_path):
    bad = tmp_path / "bad.eds"
    bad.write_text("[DeviceInfo]\nVendorName=x\n\n[6041]\nObjectType=0x7\n")  # no ParameterName
    with pytest.raises(EdsError) as exc:
        load_eds(bad)
    assert str(exc.value) == f"{bad}: not a valid EDS: NoOptionError: No option 'ParameterName' in section: '6041'"
    with pytest.raises(EdsError) as exc:
        load_eds(tmp_path / "nope.eds")
    assert str(exc.value) == f"{tmp_path / 'nope.eds'}: EDS not found"


@pytest.mark.parametrize("node,ms,word", [(1, 1, "01000100"), (127, 65535, "ffff7f00"), (0x12, 0x3456, "56341200")])
def test_master_loss_steps_pack_node_and_time(node, ms, word):
    steps = master_loss_steps(node, ms)
    assert [(st.index, st.subindex, st.data.hex(), st.what, st.write) for st in steps] == [
        (0x1016, 1, word, "consumer heartbeat time 1", True), (0x6007, 0, "0300", "abort connection option code", True)]


@pytest.mark.parametrize("node,ms,message", [
    (0, 125, "master_node_id = 0 is outside 1..127"),
    (128, 125, "master_node_id = 128 is outside 1..127"),
    (True, 125, "master_node_id must be an int in 1..127, got bool"),
    (127, 0, "consumer_ms = 0 is outside 1..65535 ms (0x1016 bits 0..15)"),
    (127, 65536, "consumer_ms = 65536 is outside 1..65535 ms (0x1016 bits 0..15)"),
    (127, 125.0, "consumer_ms must be an int in 1..65535 ms (0x1016 bits 0..15), got float 125.0"),
])
def test_master_loss_steps_refuse_what_0x1016_cannot_hold(node, ms, message):
    with pytest.raises(CanopenInputError) as exc:
        master_loss_steps(node, ms)
    assert str(exc.value) == message


def _od_state(o, seen=None):
    """Every attribute of every object of an object dictionary, recursively (``parent`` links left out:
    they are checked by identity), sets as sorted lists."""
    seen = set() if seen is None else seen
    if isinstance(o, (int, float, str, bytes, bool, type(None))):
        return o
    if isinstance(o, (set, frozenset)):
        return sorted(map(repr, o))
    if isinstance(o, (list, tuple)):
        return [_od_state(x, seen) for x in o]
    if isinstance(o, dict):
        return {repr(k): _od_state(v, seen) for k, v in o.items()}
    if id(o) in seen:
        return f"<{type(o).__name__} again>"
    seen.add(id(o))
    return {type(o).__name__: {k: _od_state(v, seen) for k, v in vars(o).items() if k != "parent"}}


@pytest.mark.parametrize("node_id", [None, 1, 2])
def test_each_load_is_canopens_own_parse_and_a_fresh_copy(tmp_path, node_id):
    """load_eds parses a text once and hands out copies: each equal to canopen's own parse of the file,
    attribute by attribute, and independent (a change to one is not in the next); a file changed under
    the same name is parsed anew."""
    import io

    import canopen.objectdictionary as cod

    path = tmp_path / "drive.eds"
    shutil.copy(default_eds_path(), path)
    fh = io.StringIO(path.read_text())
    fh.name = str(path)
    want = _od_state(cod.import_od(fh, node_id))
    a, b = load_eds(path, node_id=node_id), load_eds(path, node_id=node_id)
    assert _od_state(a) == want and _od_state(b) == want
    assert a is not b and all(a[i] is not b[i] and b[i].parent is b for i in b)
    a[0x1018][1].default = 0xBAD
    assert load_eds(path, node_id=node_id)[0x1018][1].default == b[0x1018][1].default != 0xBAD
    text = path.read_text()
    assert "ProductNumber=0x00000402" in text
    path.write_text(text.replace("ProductNumber=0x00000402", "ProductNumber=0x00000403"))  # not the cached text
    fh = io.StringIO(path.read_text())
    fh.name = str(path)
    assert _od_state(load_eds(path, node_id=node_id)) == _od_state(cod.import_od(fh, node_id)) != want
