"""Fuzzing the master with random frames and the profile loaders with random files (hypothesis).

The master may refuse a frame only with a typed emacheck error (fail closed:
it latches and quick-stops); any other exception is a crash. Garbage with
COB-IDs no drive uses must not stop the cyclic exchange. Profile loaders may
refuse a file only with :class:`hil.errors.ProfileError` naming the file and the
field; text that is no profile by construction must be refused so, and variants
that are valid by construction must load.
"""

from __future__ import annotations

import math
import re
import tomllib

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from hil.canopen.frame import Frame
from hil.canopen.process import DriveMode, Setpoint
from hil.errors import KNOWN_ERRORS, ProfileError
from hil.master.link import CanopenLink
from hil.profile.load import load_actuation, load_check, load_simrig
from hil.transport import InProcessTransport
from sim.plant import RigPlant
from support.canopen_rig import cyclic_master, make_master, make_pair
from support.profiles import load_profile_data, write_profile_variant

ACT = load_actuation()
SIM = load_simrig()

frames = st.builds(lambda cid, data: Frame(cid, data), st.integers(0, 0x7FF), st.binary(min_size=0, max_size=8))
#: COB-IDs no drive uses (node ids 1, 2 and the NMT/SYNC/EMCY/PDO/SDO/heartbeat ranges excluded)
foreign = st.integers(0, 0x7FF).filter(lambda c: c & 0x7F not in (0, 1, 2) and c not in (0x000, 0x080))


@pytest.fixture(scope="module")
def cyclic():
    """A link in the cyclic phase on its own virtual channel (python-can virtual channels are
    process-global by name: a shared name would let other tests' traffic in)."""
    pair = make_pair(RigPlant(SIM.params, np.random.default_rng(1)))
    tr = InProcessTransport(pair, ACT.timing.sync_period_s)
    link = CanopenLink(make_master(), tr)
    state = {"link": link, "smp": link.first_sample()}
    yield state
    tr.close()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(frames, min_size=1, max_size=40))
def test_random_frames_never_crash_the_master(batch):
    m = make_master()
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
    # a master through its preflight, cyclic with both drives alive (heartbeats at t = 0)
    m = cyclic_master(ACT, RigPlant(SIM.params, np.random.default_rng(1)))
    for f in batch:
        try:
            m.on_frame(f, 0.01)
        except KNOWN_ERRORS:
            assert m.fault is not None and m.quick_stop
    try:  # a poll in the cyclic phase sends at most the master's own heartbeat (0x700 + 127)
        assert {f.arbitration_id for f in m.poll(0.01)} <= {0x77F}
    except KNOWN_ERRORS:
        assert m.fault is not None and m.quick_stop


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.builds(lambda c, d: Frame(c, d), foreign, st.binary(max_size=8)), min_size=1, max_size=50))
def test_garbage_bursts_on_foreign_cob_ids_do_not_stall_the_cycle(cyclic, burst):
    link, smp = cyclic["link"], cyclic["smp"]
    before = link.m.unknown_frames
    for f in burst:  # a burst of garbage lands on the master's bus in the middle of a cycle
        link.tr.inject(f, link.tr.now())
    hold = Setpoint(DriveMode.POSITION, smp.phi1_rad), Setpoint(DriveMode.POSITION, smp.phi2_rad)
    t0 = smp.t_s
    link.exchange(*hold)
    smp = cyclic["smp"] = link.exchange(*hold)
    assert smp.t_s == pytest.approx(t0 + 2 * ACT.timing.sync_period_s) and link.m.fault is None
    assert link.m.unknown_frames - before == len(burst)


_TOML_TEXT = st.text(alphabet=st.sampled_from(list("[]=.\"'#\n abcdefghijklmnopqrstuvwxyz_0123456789-+e")),
                     max_size=300)
#: a line no TOML document holds wherever it comes (after a key, in a comment's next line, in an
#: array, in an unterminated string): text that ends with it is not TOML, whatever precedes it
_NOT_TOML = "\n[[[\n"

_scalars = st.one_of(st.integers(-10**12, 10**12), st.floats(allow_nan=True, allow_infinity=True),
                     st.booleans(), st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=5))

_LOADERS = (("actuation.toml", load_actuation), ("check.toml", load_check), ("simrig.toml", load_simrig))
#: what every profile of that kind must have: the top-level keys of the shipped one (all required)
_REQUIRED = {name: frozenset(load_profile_data(name)) for name, _ in _LOADERS}
#: the table and field names of the shipped profiles, so that random documents come near them
_NAMES = sorted({k for name, _ in _LOADERS for t, v in load_profile_data(name).items()
                 for k in ([t] + (list(v) if isinstance(v, dict) else []))})
_keys = st.one_of(st.sampled_from(_NAMES), st.from_regex(r"[a-z_][a-z0-9_]{0,11}", fullmatch=True))
#: valid TOML with a random structure of profile-like names
_TOML_DOCS = st.dictionaries(_keys, st.one_of(_scalars, st.dictionaries(_keys, _scalars, max_size=6)),
                             max_size=8).map(tomli_w.dumps)


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(_TOML_TEXT.map(lambda t: t + _NOT_TOML), _TOML_TEXT, _TOML_DOCS))
def test_random_profile_text_is_refused_with_a_profile_error(tmp_path_factory, text):
    """Text that is no profile by construction, checked without the loaders: not TOML (random text
    ending in a line no TOML holds, or random text tomllib refuses), or TOML that lacks a top-level
    table or field every profile of that kind has. Each loader must refuse it with a ProfileError
    naming the file, and for TOML the field."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        doc = None
    if text.endswith(_NOT_TOML):
        assert doc is None, text  # the construction holds
    if doc is not None:  # a random document with every required key of a profile is not "invalid by construction"
        assume(all(not req <= set(doc) for req in _REQUIRED.values()))
    p = tmp_path_factory.mktemp("fz") / "p.toml"
    p.write_text(text)
    for name, load in _LOADERS:
        with pytest.raises(ProfileError) as exc:
            load(p)
        msg = str(exc.value)
        if doc is None:
            assert msg.startswith(f"{p}: not valid TOML"), (name, msg)
        else:
            assert msg.startswith(f"{p.name}: ") and re.search(r"'[^']+'", msg), (name, msg)


@settings(max_examples=80, deadline=None)
@given(st.data())
def test_mutated_check_profile_is_loaded_or_refused_naming_the_field(tmp_path_factory, data):
    base = load_profile_data("check.toml")
    table = data.draw(st.sampled_from(sorted(base)))
    key = data.draw(st.sampled_from(sorted(base[table])))
    value = data.draw(_scalars)
    p = write_profile_variant("check.toml", tmp_path_factory.mktemp("fz") / "check.toml", {table: {key: value}})
    try:
        load_check(p, ACT)
    except ProfileError as exc:
        assert f"{table}." in str(exc) or "safety." in str(exc) or "force_fight." in str(exc) \
            or "calibration." in str(exc) or "approach." in str(exc), str(exc)


@settings(max_examples=40, deadline=None)
@given(st.data())
def test_valid_check_variants_load_with_the_values_written(tmp_path_factory, data):
    """Every value of the check profile moved at once to within 10 % below the shipped one stays
    inside every range and cross-check (the force fight below its limits, the sweep inside the
    stroke limit, the speeds below the velocity limit): valid by construction, the variant loads,
    with exactly the values written."""
    overrides: dict = {}
    for table, kv in load_profile_data("check.toml").items():
        for key, v in kv.items():
            assert isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0, (table, key, v)
            new = data.draw(st.integers(math.ceil(0.9 * v), v) if isinstance(v, int) else st.floats(0.9 * v, v))
            overrides.setdefault(table, {})[key] = new
    p = write_profile_variant("check.toml", tmp_path_factory.mktemp("fz") / "check.toml", overrides)
    chk = load_check(p, ACT)
    for table, kv in overrides.items():
        for key, v in kv.items():
            assert getattr(getattr(chk, table), key) == v, (table, key)
