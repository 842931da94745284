"""Supervisor limits one by one, hard caps no profile can raise, and bad input refused clearly."""

from __future__ import annotations

import dataclasses
import math
import shutil

import numpy as np
import pytest

from hil.canopen.process import DriveMode, Sample, Setpoint
from hil.check.supervisor import Limits, Supervisor
from hil.cli import main
from hil.errors import ProfileError
from hil.profile.config import HARD_MAX_FORCE_FRACTION, HARD_MAX_STALE_CYCLES
from hil.profile.load import default_profile_path, load_check
from support.profiles import write_profile_variant

T = 0.002
HOLD = Setpoint(DriveMode.DISABLED, 0.0)


def _stream(n: int, rng, **override) -> list[Sample]:
    """Samples of a rig at rest with sensor noise; ``override[k] = (index, field, value)``."""
    out = []
    for k in range(n):
        f = dict(t_s=k * T, phi1_rad=0.0, phi2_rad=0.0, s1_mm=rng.uniform(-0.01, 0.01),
                 s2_mm=rng.uniform(-0.01, 0.01), F1_N=rng.normal(0, 10), F2_N=rng.normal(0, 10))
        for idx, name, value in override.values():
            if k >= idx:
                f[name] = value(k) if callable(value) else value
        out.append(Sample(**f))
    return out


def _first_violation(sup: Supervisor, samples: list[Sample], sp=(HOLD, HOLD)):
    for k, smp in enumerate(samples):
        v = sup.check(smp, *sp)
        if v is not None:
            return k, v
    return None, None


@pytest.mark.parametrize("name,override,limit", [
    ("force", {"a": (50, "F1_N", 8001.0)}, "max_force_N"),
    ("fight", {"a": (50, "F1_N", 7100.0), "b": (50, "F2_N", -7100.0)}, "max_force_fight_N"),
    ("imbalance", {"a": (50, "F1_N", 2600.0)}, "max_force_imbalance_N"),
    ("stroke", {"a": (50, "s2_mm", -19.6), "b": (50, "phi2_rad", -19.6 * 5.026548245743669)}, "max_stroke_mm"),
    ("velocity", {"a": (50, "phi1_rad", lambda k: (k - 50) * 0.03 * 5.026548245743669),
                  "b": (50, "s1_mm", lambda k: (k - 50) * 0.03)}, "max_velocity_mm_per_s"),
    ("d_plausibility", {"a": (50, "s1_mm", 0.7)}, "max_d_int_mm"),
    ("lvdt_frozen", {"a": (50, "s2_mm", 0.004)}, "max_frozen_cycles"),
    ("nan", {"a": (50, "F2_N", math.nan)}, "sensor_invalid"),
])
def test_each_limit_trips_on_the_first_sample_beyond_it(actuation, check_profile, name, override, limit):
    sup = Supervisor(actuation, check_profile)
    k, v = _first_violation(sup, _stream(200, np.random.default_rng(1), **override))
    assert v is not None and v.limit == limit, v
    lim = Limits.of(actuation, check_profile)
    expected = {"max_frozen_cycles": 50 + lim.max_frozen_cycles + 1,
                "max_velocity_mm_per_s": 51}.get(limit, 50)
    assert k == expected
    assert sup.check(_stream(1, np.random.default_rng(2))[0], HOLD, HOLD) is v  # latched


def test_following_error_and_stale_samples(actuation, check_profile):
    sup = Supervisor(actuation, check_profile)
    i = actuation.mechanics.i_total_rad_per_mm
    smp = _stream(10, np.random.default_rng(3))
    far = Setpoint(DriveMode.POSITION, 0.51 * i)
    assert sup.check(smp[0], far, HOLD).limit == "max_following_error_mm"
    sup = Supervisor(actuation, check_profile)
    assert sup.check(smp[0], HOLD, HOLD) is None
    gap = dataclasses.replace(smp[1], t_s=smp[0].t_s + (check_profile.safety.max_stale_cycles + 2) * T)
    assert sup.check(gap, HOLD, HOLD).limit == "max_stale_cycles"


def test_hard_caps_hold_even_for_a_check_built_past_the_loader(actuation, check_profile):
    s = dataclasses.replace(check_profile.safety, max_force_N=1e6, max_force_fight_N=1e6,
                            max_force_imbalance_N=1e6, max_stroke_mm=199.0, max_velocity_mm_per_s=999.0,
                            max_following_error_mm=9.0, max_d_int_mm=9.0, max_stale_cycles=999,
                            max_frozen_cycles=9999)
    lim = Limits.of(actuation, dataclasses.replace(check_profile, safety=s))
    f_lim = actuation.mechanics.limit_load_N
    assert lim.max_force_N == HARD_MAX_FORCE_FRACTION * f_lim == 10000.0
    assert lim.max_force_fight_N == 0.2 * f_lim and lim.max_force_imbalance_N == 0.1 * f_lim
    assert lim.max_stroke_mm == actuation.mechanics.stroke_limit_mm
    assert (lim.max_velocity_mm_per_s, lim.max_following_error_mm, lim.max_d_int_mm) == (50.0, 2.0, 2.0)
    assert (lim.max_stale_cycles, lim.max_frozen_cycles) == (HARD_MAX_STALE_CYCLES, 100)


@pytest.mark.parametrize("variant,message", [
    (dict(overrides={"safety": {"max_force_fight_N": 9000.0}}),
     r"field 'safety.max_force_fight_N' = 9000.0 is above the hard cap 8000 N"),
    (dict(overrides={"safety": {"max_force_imbalance_N": 5000.0}}),
     r"field 'safety.max_force_imbalance_N' = 5000.0 is above the hard cap 4000 N"),
    (dict(overrides={"safety": {"max_stale_cycles": 6}}),
     r"field 'safety.max_stale_cycles' = 6 is above the hard cap 5"),
    (dict(overrides={"safety": {"max_frozen_cycles": 101}}),
     r"field 'safety.max_frozen_cycles' = 101 is above the hard cap 100"),
    (dict(overrides={"safety": {"max_force_fight_N": 5000.0}}),
     r"'force_fight.amplitude_fraction_of_limit' = 0.15 of mechanics.limit_load_N = 40000 N in the shipped "
     r"actuation.toml gives 6000 N, not below safety.max_force_fight_N"),
    (dict(overrides={"safety": {"max_stale_cycles": 2.5}}), r"field 'safety.max_stale_cycles' must be an integer"),
    (dict(overrides={"safety": {"max_lag_s": 0.6}}), r"field 'safety.max_lag_s' = 0.6 is above the hard cap 0.5"),
    (dict(rename={"safety.max_lag_s": "max_lag_ms"}), r"max_lag_ms.*did you mean 'max_lag_s'"),
])
def test_profile_values_above_hard_caps_are_refused_naming_the_field(tmp_path, actuation, variant, message):
    p = write_profile_variant("check.toml", tmp_path / "check.toml", **variant)
    with pytest.raises(ProfileError, match=message):
        load_check(p, actuation)


def test_a_check_profile_that_no_longer_fits_the_actuations_limit_load_names_both_files(tmp_path, capsys):
    """The shipped check's force fight (0.15 of the limit load) under an actuation whose limit load was raised
    to 50 kN: 7500 N, above the check's 7000 N force-fight limit. The problem is the pair of files; the
    message names both (found by the readers' fuzzing: exit 3 naming only check.toml)."""
    prof = write_profile_variant("actuation.toml", tmp_path / "rig-a.toml",
                                 overrides={"mechanics": {"limit_load_N": 50000.0}})
    assert main(["profile", "check", str(prof)]) == 3
    err = capsys.readouterr()
    text = err.out + err.err
    assert ("check.toml: field 'force_fight.amplitude_fraction_of_limit' = 0.15 of mechanics.limit_load_N = "
            "50000 N in rig-a.toml gives 7500 N, not below safety.max_force_fight_N = 7000 N") in " ".join(text.split())


_EDS_PRODUCT_CODE = ("[1018sub2]\nParameterName=Product code\nObjectType=0x7\nDataType=0x0007\nAccessType=ro\n"
                     "DefaultValue=0x00000402")
_EDS_PRODUCT_NUMBER = "ProductNumber=0x00000402"


def test_eds_of_another_drive_is_refused_before_the_bus(tmp_path, capsys):
    # the EDS is not TOML: its text is edited, and the edit must have found its line
    text = default_profile_path("ema_drive.eds").read_text()
    assert _EDS_PRODUCT_CODE in text and _EDS_PRODUCT_NUMBER in text
    eds = tmp_path / "other.eds"
    eds.write_text(text.replace(_EDS_PRODUCT_CODE, _EDS_PRODUCT_CODE.replace("0x00000402", "0x00000999"))
                   .replace(_EDS_PRODUCT_NUMBER, _EDS_PRODUCT_NUMBER.replace("0x00000402", "0x00000999")))
    act = write_profile_variant("actuation.toml", tmp_path / "actuation.toml", {"canopen": {"eds": "other.eds"}})
    rc = main(["dry-run", "--profile", str(act), "--out", str(tmp_path / "d"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 3
    # the plan names the profile key, the object (both drives: one EDS) and both values
    assert ("canopen.product_code: 0x1018:02 at ema1, ema2: other.eds: identity 0x1018:02 = 0x00000999 does not "
            "match the profile's canopen.product_code = 0x00000402: the EDS describes another device") in err
    assert not (tmp_path / "d").exists()  # nothing ran, nothing was sent


@pytest.fixture(scope="module")
def short_run(tmp_path_factory, actuation, check_profile, simrig):
    """A short aborted dry-run (an EMCY at 3 s) to mutate its recordings."""
    from hil.cli.dry_run import dry_run
    from sim.faults import Fault
    out = tmp_path_factory.mktemp("bad") / "run"
    dry_run(actuation, check_profile, simrig, out, faults=[Fault("emcy_over_current", 1, 3.0)])
    return out


def _analyze_refuses(capsys, path, message):
    # (a run folder's recording mutated after its check is refused for that alone: accepted here, so that the
    # reader's own refusal is what is tested)
    assert main(["analyze", str(path), "--accept-modified"]) == 3
    err = capsys.readouterr().err
    assert message in err, err


@pytest.mark.parametrize("mutate,message", [
    (lambda L: L[:5] + [L[5].replace(L[5].split(",")[3], "nan", 1)] + L[6:], "line 6: column 's1' [mm] is nan"),
    (lambda L: L[:5] + [L[6], L[5]] + L[7:], "line 7: time not increasing"),
    (lambda L: [L[0].replace(",F2,", ",F2x,")] + L[1:], "line 1: missing column(s) F2"),
    (lambda L: [L[0]] + [",".join([f"{float(r.split(',')[0]) * 1000:.1f}"] + r.split(",")[1:]) for r in L[1:]],
     "(time in ms?)"),
    (lambda L: [L[0]] + [",".join(r.split(",")[:3] + [f"{float(r.split(',')[3]) * 1000:.1f}"] + r.split(",")[4:])
                         for r in L[1:]], "(stroke in um?)"),
])
def test_bad_recordings_are_refused_with_line_and_unit(tmp_path, capsys, short_run, mutate, message):
    lines = (short_run / "signals.csv").read_text().splitlines()
    p = tmp_path / "rec.csv"
    p.write_text("\n".join(mutate(lines)) + "\n")
    _analyze_refuses(capsys, p, message)


def test_can_log_with_garbage_lines_is_refused_but_a_cut_last_line_is_not(tmp_path, capsys, short_run, actuation):
    from hil.record.canlog import decode_can_log
    run = tmp_path / "run"
    shutil.copytree(short_run, run)
    (run / "signals.csv").unlink()
    log = (run / "can.log").read_text().splitlines()
    (run / "can.log").write_text("\n".join(log) + "\n" + log[-1][:17])  # killed mid-line
    dec = decode_can_log(run / "can.log", actuation)
    assert "last line incomplete (recording cut short), dropped" in dec.signals.notes
    (run / "can.log").write_text("\n".join(log[:100] + ["garbage ## line"] + log[100:]) + "\n")
    _analyze_refuses(capsys, run, "line 101: not a candump frame line")


@pytest.mark.parametrize("name", ["can.log", "can.log.gz"])
def test_the_can_log_reader_closes_its_file_however_the_reading_ends(tmp_path, monkeypatch, name):
    """A reading stopped early (a bad frame raised by the decoder, a consumer that stops) closes the file,
    plain or gzipped (python-can's reader closes it only at the end of the file)."""
    import gzip

    from hil.record import canlog

    text = "(0.000000) can0 080#\n(0.001000) can0 181#0102\n(0.002000) can0 080#\n"
    path = tmp_path / name
    if name.endswith(".gz"):
        with gzip.open(path, "wt") as f:
            f.write(text)
    else:
        path.write_text(text)
    opened = []
    real = gzip.open if name.endswith(".gz") else open

    def spy(*args, **kw):
        opened.append(real(*args, **kw))
        return opened[-1]

    if name.endswith(".gz"):
        monkeypatch.setattr(canlog.gzip, "open", spy)
    else:
        monkeypatch.setattr(canlog, "open", spy, raising=False)  # the module's name for the builtin
    counts = {"frames": 0, "bad": 0}
    frames = canlog._frames(path, counts)
    assert next(frames)[0].arbitration_id == 0x080
    assert len(opened) == 1 and not opened[0].closed
    frames.close()  # the reading ends after one frame
    assert opened[0].closed and counts == {"frames": 1, "bad": 0}


def test_a_gzipped_can_log_decodes_as_the_plain_one(tmp_path, short_run, actuation):
    """``can.log.gz`` is read through gzip (the line check and the frame reader): the same signals and
    counts as the plain log. (The whole analysis of a bare can.log.gz against the check's own result is
    test_dry_run.py's, slow.)"""
    import gzip

    from hil.record.canlog import decode_can_log
    from hil.record.runfolder import is_can_log
    from hil.record.signals_csv import EXTRA_COLUMNS, SIGNAL_COLUMNS

    gz = tmp_path / "can.log.gz"
    with gzip.open(gz, "wb") as fh:
        fh.write((short_run / "can.log").read_bytes())
    assert is_can_log(gz)
    plain, packed = decode_can_log(short_run / "can.log", actuation), decode_can_log(gz, actuation)
    assert packed.signals.n == plain.signals.n > 1000
    assert (packed.frames, packed.syncs, packed.incomplete_cycles, packed.bad_lines) == \
        (plain.frames, plain.syncs, plain.incomplete_cycles, plain.bad_lines)
    assert packed.signals.notes == tuple(n.replace("CAN log can.log:", "CAN log can.log.gz:")
                                         for n in plain.signals.notes)
    assert packed.signals.notes[0].startswith("decoded from CAN log can.log.gz: ")
    for name in SIGNAL_COLUMNS + EXTRA_COLUMNS:
        np.testing.assert_array_equal(getattr(packed.signals, name), getattr(plain.signals, name), err_msg=name)


def test_the_can_log_reader_times_a_sample_by_its_sync_period_not_by_count_or_stamp(tmp_path, short_run, actuation):
    """A SYNC period with no SYNC in the log (the loop-timed SYNC skipped one) leaves its slot empty:
    the samples after it keep their own times (counted, they would all be one period early). A SYNC
    logged 0.4 T late, its answers with it, still gives its sample the time of its period (by its
    stamp it would be 0.4 T late; more than T/2 late, it is taken for the next period), as the
    master timed it in the run (hil.canopen.cycle.SyncSchedule)."""
    from hil.record.canlog import decode_can_log

    T = actuation.timing.sync_period_s
    lines = (short_run / "can.log").read_text().splitlines()
    base = decode_can_log(short_run / "can.log", actuation).signals.t
    syncs = [i for i, line in enumerate(lines) if " 080#" in line]
    assert len(syncs) - 1 <= len(base) <= len(syncs) and len(base) > 1000  # (an aborted run: the last cut off)

    def late(line: str, dt: float) -> str:
        stamp, rest = line[1:].split(")", 1)
        return f"({float(stamp) + dt:.6f}){rest}"

    j, k = len(syncs) // 2, len(syncs) // 2 + 10  # SYNC j's cycle left out, SYNC k's cycle late
    np.testing.assert_allclose(np.diff(base[:k + 10]), T, atol=1e-9)  # every SYNC on time there
    mutated = (lines[:syncs[j]] + lines[syncs[j + 1]:syncs[k]]
               + [late(line, 0.4 * T) for line in lines[syncs[k]:syncs[k + 1]]] + lines[syncs[k + 1]:])
    (tmp_path / "can.log").write_text("\n".join(mutated) + "\n")
    t = decode_can_log(tmp_path / "can.log", actuation).signals.t
    np.testing.assert_allclose(t, np.delete(base, j), atol=1e-9)
