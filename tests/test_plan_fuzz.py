"""EDS files nobody wrote for emacheck, as the planner meets them: mutations of an EDS (objects, sub-indices,
access, defaults, PDO records and [DeviceInfo] removed or changed) either plan or are refused as bad input
(PlanError / EdsError / ProfileError), never an internal error; ``profile check`` exits 0 or 3."""

from __future__ import annotations

import configparser
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hil.canopen.errors import EdsError
from hil.canopen.plan import PlanError
from hil.errors import ProfileError
from hil.profile.load import default_profile_path, load_actuation
from hil.profile.rig import plan_for
from support.profiles import write_profile_variant

SECTIONS = None


def _sections() -> list[str]:
    ini = configparser.ConfigParser(interpolation=None, strict=False)
    ini.optionxform = str
    ini.read(default_profile_path("ema_drive.eds"))
    return ini.sections()


_ALL = _sections()
_OBJECTS = [s for s in _ALL if len(s) >= 4 and all(c in "0123456789ABCDEFabcdefsub" for c in s)]

mutation = st.one_of(
    st.tuples(st.just("remove"), st.sampled_from(_OBJECTS)),
    st.tuples(st.just("access"), st.sampled_from(_OBJECTS), st.sampled_from(["ro", "wo", "rw", "rww", "rwr", "const"])),
    st.tuples(st.just("default"), st.sampled_from(_OBJECTS),
              st.sampled_from(["", "0", "0x80000181", "$NODEID+0x180", "junk", "0x00000080", "-1", "1.5"])),
    st.tuples(st.just("pdo"), st.sampled_from(_OBJECTS), st.sampled_from(["0", "1"])),
    st.tuples(st.just("type"), st.sampled_from(_OBJECTS),
              st.sampled_from(["0x0002", "0x0003", "0x0004", "0x0005", "0x0006", "0x0007", "0x0008", "0x0009"])),
    st.tuples(st.just("info"), st.sampled_from(["VendorNumber", "ProductNumber", "RevisionNumber", "NrOfTXPDO"]),
              st.sampled_from(["", "0", "0x00000999"])),
)


def _mutate(src: Path, dest: Path, muts) -> None:
    ini = configparser.ConfigParser(interpolation=None, strict=False)
    ini.optionxform = str
    ini.read(src)
    keys = {"access": "AccessType", "default": "DefaultValue", "pdo": "PDOMapping", "type": "DataType"}
    for m in muts:
        kind, name = m[0], m[1]
        if kind == "remove":
            if ini.has_section(name):
                ini.remove_section(name)
        elif kind == "info":
            if m[2]:
                ini["DeviceInfo"][name] = m[2]
            else:
                ini.remove_option("DeviceInfo", name)
        elif ini.has_section(name) and "ParameterName" in ini[name] and "ObjectType" in ini[name] \
                and ini[name].get("ObjectType", "0x7").lower() in ("0x7", "7"):
            if m[2] == "" and kind == "default":
                ini.remove_option(name, "DefaultValue")
            else:
                ini[name][keys[kind]] = m[2]
    with open(dest, "w") as fh:
        ini.write(fh, space_around_delimiters=False)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(mutation, min_size=1, max_size=6))
def test_a_mutated_eds_plans_or_is_refused_as_bad_input(tmp_path, muts):
    eds = tmp_path / "vendor.eds"
    _mutate(default_profile_path("ema_drive.eds"), eds, muts)
    prof = write_profile_variant("actuation.toml", tmp_path / "act.toml", {"canopen": {"eds": str(eds)}})
    try:
        rig = plan_for(load_actuation(prof), prof)
    except (PlanError, EdsError, ProfileError) as exc:
        assert str(exc)  # a message naming what is wrong
        if isinstance(exc, PlanError):
            assert exc.problems and all(p.key and p.message for p in exc.problems)
        return
    # a plan: every signal of both EMAs sits in a PDO of the layout
    plan = rig.plan
    cobs = {p.cob_id for n in plan.nodes for p in n.layout.pdos}
    assert all(c.cob_id in cobs for c in plan.channels)
    assert plan.load.load_worst < 0.5


@pytest.mark.parametrize("text", ["", "[DeviceInfo]\n", "garbage without sections", "[1000]\nParameterName=x\n",
                                  "[1018]\nParameterName=Identity\nObjectType=0x9\nSubNumber=2\n\n[1018sub0]\n"])
def test_a_broken_eds_file_is_bad_input_for_profile_check(tmp_path, capsys, text):
    from hil.cli import main

    eds = tmp_path / "vendor.eds"
    eds.write_text(text)
    prof = write_profile_variant("actuation.toml", tmp_path / "act.toml", {"canopen": {"eds": str(eds)}})
    assert main(["profile", "check", str(prof)]) == 3
    captured = capsys.readouterr()
    assert "internal error" not in captured.err and "Traceback" not in captured.err + captured.out
