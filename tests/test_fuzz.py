"""Fuzzing the master with random frames and the profile loaders with random files (hypothesis).

The master may refuse a frame only with a typed emacheck error (fail closed:
it latches and quick-stops); any other exception is a crash. Garbage with
COB-IDs no drive uses must not stop the cyclic exchange. Profile loaders may
refuse a file only with :class:`hil.errors.ProfileError`.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hil.link import CanopenLink
from hil.transport import InProcessTransport, _to_msg
from hil.canopen.od import load_drive_od
from hil.errors import KNOWN_ERRORS, ProfileError
from hil.master import MasterCore
from hil.canopen.frame import Frame
from hil.profiles import default_profile_path, load_actuation, load_check, load_simrig
from hil.canopen.process import DriveMode, Setpoint
from sim.plant import RigPlant
from sim.drives import SimDrivePair

ACT = load_actuation()
SIM = load_simrig()

frames = st.builds(lambda cid, data: Frame(cid, data), st.integers(0, 0x7FF), st.binary(min_size=0, max_size=8))
#: COB-IDs no drive uses (node ids 1, 2 and the NMT/SYNC/EMCY/PDO/SDO/heartbeat ranges excluded)
foreign = st.integers(0, 0x7FF).filter(lambda c: c & 0x7F not in (0, 1, 2) and c not in (0x000, 0x080))


@pytest.fixture(scope="module")
def cyclic():
    """A link in the cyclic phase on its own virtual channel (python-can virtual channels are
    process-global by name: a shared name would let other tests' traffic in)."""
    pair = SimDrivePair(RigPlant(SIM.params, np.random.default_rng(1)),
                        lambda node_id=None: load_drive_od(None, node_id=node_id))
    tr = InProcessTransport(pair, ACT.timing.sync_period_s, channel="emacheck-fuzz-test")
    link = CanopenLink(MasterCore(ACT), tr)
    state = {"link": link, "smp": link.first_sample()}
    yield state
    tr.close()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(frames, min_size=1, max_size=40))
def test_random_frames_never_crash_the_master(batch):
    m = MasterCore(ACT)
    m.start(0.0)
    for k, f in enumerate(batch):  # during the preflight
        try:
            m.on_frame(f, 0.001 * k)
            m.poll(0.001 * k)
        except KNOWN_ERRORS:
            assert m.fault is not None and m.quick_stop  # typed, latched, fail closed
            break


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(frames, min_size=1, max_size=30))
def test_random_frames_in_the_cyclic_phase_are_refused_typed_or_ignored(batch):
    m = MasterCore(ACT)
    # a master that believes it is cyclic with both drives alive
    m._gen = None
    from hil.master import Phase
    m.phase = Phase.CYCLIC
    for d in m.drives.values():
        d.last_heartbeat_s = 0.0
    for f in batch:
        try:
            m.on_frame(f, 0.01)
        except KNOWN_ERRORS:
            assert m.fault is not None and m.quick_stop
    try:
        assert m.poll(0.01) == []  # nothing to send from a poll in the cyclic phase
    except KNOWN_ERRORS:
        assert m.fault is not None and m.quick_stop


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.builds(lambda c, d: Frame(c, d), foreign, st.binary(max_size=8)), min_size=1, max_size=50))
def test_garbage_bursts_on_foreign_cob_ids_do_not_stall_the_cycle(cyclic, burst):
    link, smp = cyclic["link"], cyclic["smp"]
    before = link.m.unknown_frames
    for f in burst:  # a burst of garbage lands on the master's bus in the middle of a cycle
        link.tr.slave_bus.send(_to_msg(f, link.tr.now(), rx=True))
    hold = Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad)
    t0 = smp.t_s
    link.exchange(*hold)
    smp = cyclic["smp"] = link.exchange(*hold)
    assert smp.t_s == pytest.approx(t0 + 2 * ACT.timing.sync_period_s) and link.m.fault is None
    assert link.m.unknown_frames - before == len(burst)


_TOML_TEXT = st.text(alphabet=st.sampled_from(list("[]=.\"'#\n abcdefghijklmnopqrstuvwxyz_0123456789-+e")),
                     max_size=300)


@settings(max_examples=80, deadline=None)
@given(_TOML_TEXT)
def test_random_profile_text_is_refused_with_a_profile_error(tmp_path_factory, text):
    p = tmp_path_factory.mktemp("fz") / "p.toml"
    p.write_text(text)
    for load in (load_actuation, load_check, load_simrig):
        try:
            load(p)
        except ProfileError:
            pass


_scalars = st.one_of(st.integers(-10**12, 10**12), st.floats(allow_nan=True, allow_infinity=True),
                     st.booleans(), st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=5))


@settings(max_examples=80, deadline=None)
@given(st.data())
def test_mutated_check_profile_is_loaded_or_refused_naming_the_field(tmp_path_factory, data):
    import tomllib
    base = tomllib.loads(default_profile_path("check.toml").read_text())
    table = data.draw(st.sampled_from(sorted(base)))
    key = data.draw(st.sampled_from(sorted(base[table])))
    value = data.draw(_scalars)
    lines = []
    for t, kv in base.items():
        lines.append(f"[{t}]")
        for k, v in kv.items():
            v = value if (t, k) == (table, key) else v
            if isinstance(v, bool):
                lit = "true" if v else "false"
            elif isinstance(v, float) and not np.isfinite(v):
                lit = "nan" if np.isnan(v) else ("inf" if v > 0 else "-inf")
            elif isinstance(v, str):
                lit = '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
            else:
                lit = repr(v)
            lines.append(f"{k} = {lit}")
    p = tmp_path_factory.mktemp("fz") / "check.toml"
    p.write_text("\n".join(lines) + "\n")
    try:
        load_check(p, ACT)
    except ProfileError as exc:
        assert f"{table}." in str(exc) or "safety." in str(exc) or "force_fight." in str(exc) \
            or "calibration." in str(exc) or "approach." in str(exc), str(exc)
