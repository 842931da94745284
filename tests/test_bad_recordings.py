"""Every bad input file is a clear error (issue 34): exit 3 with the file named and what is wrong, never 4,
never a traceback, never an empty output folder; and what is only unusual (a UTF-8 byte-order mark) is read.

Classes: a binary or UTF-16 profile, a folder for a file, a corrupt ``.csv.gz`` (truncated, garbage), a
CSV, TOML, EDS and CAN log with a BOM (the parsed values asserted), constant signals (analyze, serv,
diagnose), a one-row file, jumps in time and in position (named by their 1-based line, the header line 1),
two internal errors in one second (two traceback files).
"""

from __future__ import annotations

import codecs
import datetime
import gzip
import json
import warnings

import numpy as np
import pytest

from hil.canopen.errors import EdsError
from hil.canopen.frame import sync_frame
from hil.canopen.od import default_eds_path, load_eds
from hil.canopen.units import mm_to_lvdt_um, newton_to_force_dN, rad_to_increments
from hil.cli import main
from hil.cli.args import ExitCode
from hil.profile.load import default_profile_path, load_actuation
from hil.record.canlog import CanLogWriter, decode_can_log
from hil.record.runfolder import read_signals
from support.canopen_rig import shipped_rig

HEADER = "t,phi1,phi2,s1,s2,F1,F2"
FMT = ["%.4f", "%.7f", "%.7f", "%.6f", "%.6f", "%.3f", "%.3f"]


def smooth(n: int = 2000, seed: int = 5) -> np.ndarray:
    """A recording of slow sinusoidal motion with noise, columns t,phi1,phi2,s1,s2,F1,F2 (s, rad, mm, N)."""
    rng = np.random.default_rng(seed)
    t = np.arange(1, n + 1) * 0.002
    x = 2.0 * np.sin(2 * np.pi * 0.5 * t)  # [mm] 6.3 mm/s at most
    i = 5.0265
    return np.column_stack([t, x * i + rng.normal(0, 1e-3, n), x * i + rng.normal(0, 1e-3, n),
                            x + rng.normal(0, 4e-3, n), x + rng.normal(0, 4e-3, n),
                            100 * np.cos(t) + rng.normal(0, 10, n), -100 * np.cos(t) + rng.normal(0, 10, n)])


def write_csv(path, a: np.ndarray) -> None:
    np.savetxt(path, a, delimiter=",", header=HEADER, comments="", fmt=FMT)


def _err(capsys) -> str:
    out = capsys.readouterr()
    assert "Traceback" not in out.err + out.out
    return out.err


# ---------------------------------------------------------------------------------------------- profiles


@pytest.mark.parametrize("content,words", [
    (bytes(range(256)) * 4, "not a TOML text file (binary or not UTF-8: byte 128 is not UTF-8); save it as UTF-8"),
    ("a = 1\n".encode("utf-16"), "not a TOML text file (UTF-16 text: byte 0 is not UTF-8); save it as UTF-8"),
])
def test_a_binary_or_utf16_profile_is_exit_3_naming_the_file(tmp_path, capsys, content, words):
    p = tmp_path / "actuation.toml"
    p.write_bytes(content)
    for argv in (["profile", "check", str(p)], ["dry-run", "--profile", str(p), "--out", str(tmp_path / "r")],
                 ["simulate", "--check", str(p), "--out", str(tmp_path / "s")]):
        assert main(argv) == ExitCode.INPUT
        assert f"emacheck: error: {p}: {words}" in _err(capsys)
    assert not (tmp_path / "r").exists() and not (tmp_path / "s").exists()


def test_a_folder_for_a_profile_an_eds_or_a_recording_is_exit_3_naming_it(tmp_path, capsys):
    d = tmp_path / "folder.toml"
    d.mkdir()
    assert main(["profile", "check", str(d)]) == ExitCode.INPUT
    assert f"{d}: a folder, not a profile (a TOML file)" in _err(capsys)
    e = tmp_path / "drive.eds"
    e.mkdir()
    assert main(["profile", "check", str(default_profile_path("actuation.toml")), "--eds", str(e)]) == ExitCode.INPUT
    assert f"--eds {e}: a folder, not an EDS file" in _err(capsys)
    with pytest.raises(EdsError, match=f"{e}: a folder, not an EDS file"):
        load_eds(e)
    r = tmp_path / "flight.csv.gz"
    r.mkdir()
    assert main(["serv", str(r)]) == ExitCode.INPUT
    assert f"{r}: run folder without signals.csv or can.log" in _err(capsys)


def test_a_binary_eds_is_exit_3_naming_it(tmp_path, capsys):
    e = tmp_path / "drive.eds"
    e.write_bytes(b"\x00\xff\xfe" * 100)
    assert main(["profile", "check", str(default_profile_path("actuation.toml")), "--eds", str(e)]) == ExitCode.INPUT
    out = capsys.readouterr()
    assert f"canopen.eds: {e}: not a valid EDS: not UTF-8 text (byte 1); save it as UTF-8" in out.out
    assert "Traceback" not in out.out + out.err


# ------------------------------------------------------------------------------------------ corrupt gzip


@pytest.mark.parametrize("how", ["truncated", "garbage", "not gzip"])
@pytest.mark.parametrize("command", ["analyze", "serv", "diagnose"])
def test_a_corrupt_csv_gz_is_exit_3_naming_the_file(tmp_path, capsys, how, command):
    a = smooth()
    plain = tmp_path / "x.csv"
    write_csv(plain, a)
    data = gzip.compress(plain.read_bytes())
    bad = {"truncated": data[: len(data) // 2],
           "garbage": data[:20] + bytes((b * 7 + 3) % 256 for b in data[20:2000]) + data[2000:],
           "not gzip": b"PK\x03\x04 a zip file, not gzip" * 10}[how]
    p = tmp_path / "flight.csv.gz"
    p.write_bytes(bad)
    assert main([command, str(p), "--out", str(tmp_path / "out")]) == ExitCode.INPUT
    err = _err(capsys)
    assert f"emacheck: error: {p}: a corrupt or truncated gzip file, not a text CSV file" in err, err
    assert not (tmp_path / "out").exists()


def test_a_corrupt_can_log_gz_is_exit_3_naming_it(tmp_path, capsys):
    p = tmp_path / "can.log.gz"
    p.write_bytes(gzip.compress(b"(0.000000) vcan0 080#\n" * 50)[:40])
    assert main(["analyze", str(p), "--out", str(tmp_path / "o"), "--no-history"]) == ExitCode.INPUT
    assert f"{p}: a corrupt or truncated gzip file, not a CAN log" in _err(capsys)


def test_a_binary_csv_is_exit_3_naming_it(tmp_path, capsys):
    p = tmp_path / "flight.csv"
    p.write_bytes(HEADER.encode("utf-16"))
    assert main(["serv", str(p)]) == ExitCode.INPUT
    assert f"{p}: not a text CSV file (columns t,phi1,phi2,s1,s2,F1,F2): not UTF-8 text" in _err(capsys)


# ------------------------------------------------------------------------------------ a byte-order mark


def test_a_csv_with_a_bom_is_read_with_its_values(tmp_path):
    a = smooth(50)
    plain, bom = tmp_path / "plain.csv", tmp_path / "bom.csv"
    write_csv(plain, a)
    bom.write_bytes(codecs.BOM_UTF8 + plain.read_bytes())
    got, want = read_signals(bom), read_signals(plain)
    assert got.n == 50 and got.t[0] == 0.002 and got.phi1[0] == float(f"{a[0, 1]:.7f}")
    for c in HEADER.split(","):
        assert np.array_equal(getattr(got, c), getattr(want, c)), c
    gz = tmp_path / "bom.csv.gz"
    gz.write_bytes(gzip.compress(bom.read_bytes()))
    assert np.array_equal(read_signals(gz).F2, want.F2)


def test_a_toml_profile_with_a_bom_is_read_with_its_values(tmp_path, actuation):
    p = tmp_path / "actuation.toml"
    p.write_bytes(codecs.BOM_UTF8 + default_profile_path("actuation.toml").read_bytes())
    act = load_actuation(p)
    assert act.mechanics.i_total_rad_per_mm == actuation.mechanics.i_total_rad_per_mm
    assert act.mechanics.limit_load_N == 40_000.0 and act.timing.sync_period_s == 0.002
    assert act.canopen.node_ids == actuation.canopen.node_ids


def test_an_eds_with_a_bom_is_read_with_its_objects(tmp_path):
    p = tmp_path / "drive.eds"
    p.write_bytes(codecs.BOM_UTF8 + default_eds_path().read_bytes())
    got, want = load_eds(p), load_eds(None)
    assert sorted(got.indices) == sorted(want.indices) and 0x1018 in got
    assert got[0x1000].default == want[0x1000].default


def _can_log(path, rows: np.ndarray, bom: bool) -> None:
    w = CanLogWriter(path)
    plan = shipped_rig().plan
    for t, phi1, phi2, s1, s2, f1, f2 in rows:
        w.write(sync_frame(), float(t), rx=False)
        for ema, phi, s, f in ((1, phi1, s1, f1), (2, phi2, s2, f2)):
            lay = plan.node(f"ema{ema}").layout
            w.write(lay["TPDO1"].pack((0x0237, rad_to_increments(float(phi), 4096), 8)), float(t), rx=True)
            w.write(lay["TPDO2"].pack((mm_to_lvdt_um(float(s)), newton_to_force_dN(float(f)))), float(t), rx=True)
    w.close()
    if bom:
        path.write_bytes(codecs.BOM_UTF8 + path.read_bytes())


def test_a_can_log_with_a_bom_is_decoded_with_its_values(tmp_path, actuation):
    rows = smooth(30)
    _can_log(tmp_path / "plain.log", rows, bom=False)
    _can_log(tmp_path / "bom.log", rows, bom=True)
    got = decode_can_log(tmp_path / "bom.log", actuation).signals
    want = decode_can_log(tmp_path / "plain.log", actuation).signals
    assert got.n == want.n == 30
    for c in HEADER.split(","):
        assert np.array_equal(getattr(got, c), getattr(want, c)), c


# ------------------------------------------------------------------------------ nothing to analyse


def _run_folder(tmp_path, a: np.ndarray):
    d = tmp_path / "run"
    d.mkdir()
    write_csv(d / "signals.csv", a)
    return d


@pytest.mark.parametrize("command,channels,what", [
    ("analyze", "phi1, phi2, s1, s2, F1, F2", "the check"),
    ("serv", "phi1, phi2, s1, s2", "BLFserv"),
    ("diagnose", "phi1, phi2, s1, s2, F1, F2", "the diagnosis"),
])
def test_constant_signals_are_exit_3_naming_file_and_signal_and_leave_no_folder(tmp_path, capsys, command,
                                                                                 channels, what):
    a = np.zeros((2000, 7))
    a[:, 0] = np.arange(1, 2001) * 0.002
    run = _run_folder(tmp_path, a)
    argv = [command, str(run)] + (["--no-history"] if command != "diagnose" else [])
    assert main(argv) == ExitCode.INPUT
    err = _err(capsys)
    sig = run / "signals.csv"
    assert f"emacheck: error: {sig}: " in err and f"constant signal {channels} (all 2000 samples of phi1 are 0 rad)" \
        in err and f"{what} needs it to change" in err, err
    assert sorted(p.name for p in run.iterdir()) == ["signals.csv"]


def test_serv_accepts_constant_forces(tmp_path, capsys):
    """BLFserv needs no force sensors: constant forces are not refused (the motion is)."""
    a = smooth()
    a[:, 5:] = 0.0
    p = tmp_path / "flight.csv"
    write_csv(p, a)
    rc = main(["serv", str(p), "--out", str(tmp_path / "o"), "--no-history", "--no-report"])
    assert rc in (ExitCode.PASS, ExitCode.INCONCLUSIVE) and (tmp_path / "o" / "serv.json").exists()
    assert "constant" not in capsys.readouterr().err


@pytest.mark.parametrize("rows", [1, 3])
def test_a_recording_of_one_or_three_rows_is_exit_3_without_warnings(tmp_path, capsys, rows):
    p = tmp_path / "flight.csv"
    write_csv(p, smooth(rows))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning (mean of an empty slice, ...) would fail here
        assert main(["serv", str(p), "--no-history"]) == ExitCode.INPUT
        assert f"{p}: recording too short for BLFserv: {rows} samples (need >= 100)" in _err(capsys)
        assert main(["analyze", str(p), "--no-history"]) == ExitCode.INPUT
        assert f"{p}: cannot be analysed: recording too short for the check: {rows} samples (need >= 1000)" \
            in _err(capsys)
    assert sorted(x.name for x in tmp_path.iterdir()) == ["flight.csv"]


# ----------------------------------------------------------------------------------------------- jumps


@pytest.mark.parametrize("command", ["serv", "analyze", "diagnose"])
def test_a_jump_in_position_is_exit_3_naming_its_line(tmp_path, capsys, command):
    a = smooth()
    a[1500:, 3] += 0.5  # s1 steps 0.5 mm between rows 1499 and 1500 (0-based): file lines 1501 and 1502
    p = tmp_path / "joined.csv"
    write_csv(p, a)
    assert main([command, str(p), "--out", str(tmp_path / "o")]) == ExitCode.INPUT
    err = _err(capsys)
    assert f"emacheck: error: {p}: line 1502: a jump in position: column 's1' [mm] steps +0.490921 mm in one " \
           "sample (0.0008 -> 0.491721), more than the 0.256131 mm possible (twice the ram-speed cap 50 mm/s plus " \
           "10 noise sigmas)" in err, err
    assert "recordings joined, or a sensor fault" in err and not (tmp_path / "o").exists()


def test_a_jump_in_time_is_exit_3_naming_its_line(tmp_path, capsys):
    a = smooth()
    a[700:, 0] += 0.019  # 0.021 s between two samples: above 10 periods (0.02 s)
    p = tmp_path / "gap.csv"
    write_csv(p, a)
    assert main(["serv", str(p), "--out", str(tmp_path / "o")]) == ExitCode.INPUT
    err = _err(capsys)
    assert f"{p}: line 702: a jump in time: 0.021 s since the last sample (t = 1.4 s), more than 10 sample " \
           "periods (0.02 s)" in err, err
    a[700:, 0] -= 0.019 + 0.004  # t goes back 2 ms
    write_csv(p, a)
    assert main(["serv", str(p), "--out", str(tmp_path / "o")]) == ExitCode.INPUT
    assert f"{p}: line 702: time not increasing (t = 1.398 s after 1.4 s)" in _err(capsys)


def test_a_recording_joined_end_to_start_is_refused_and_one_with_a_gap_of_ten_periods_is_not(tmp_path, capsys):
    a = smooth(900)  # ends at -1.18 mm, starts at +0.01 mm
    joined = np.vstack([a, a])
    joined[900:, 0] += a[-1, 0]
    p = tmp_path / "joined.csv"
    write_csv(p, joined)
    assert main(["serv", str(p), "--out", str(tmp_path / "o")]) == ExitCode.INPUT
    assert f"{p}: line 902: a jump in position: column 'phi1' [rad] steps +5.9" in _err(capsys)
    b = smooth()
    b[700:, 0] += 0.018  # 0.02 s between two samples: 10 periods, taken (and noted as a gap)
    q = tmp_path / "gap.csv"
    write_csv(q, b)
    assert main(["serv", str(q), "--out", str(tmp_path / "o2"), "--no-report", "--no-history"]) != ExitCode.INPUT
    assert any("1 gap(s) in time" in n for n in json.loads((tmp_path / "o2" / "serv.json").read_text())["notes"])


# ------------------------------------------------------------------------------------- internal errors


def test_two_internal_errors_in_one_second_leave_two_traceback_files(monkeypatch, capsys, tmp_path):
    import hil.cli.analyze as cmd

    class Frozen(datetime.datetime):
        @classmethod
        def now(cls, tz=None):
            return cls(2026, 11, 26, 12, 0, 0)

    def boom(args):
        raise ZeroDivisionError(f"boom {args.recording}")

    monkeypatch.setattr(cmd, "cmd_analyze", boom)
    monkeypatch.setattr(datetime, "datetime", Frozen)  # both errors in the same second
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    assert main(["analyze", "first"]) == main(["analyze", "second"]) == ExitCode.INTERNAL
    err = capsys.readouterr().err.strip().splitlines()
    saved = sorted(tmp_path.glob("emacheck-internal-error-20261126-120000-*.txt"))
    assert len(saved) == 2 and len(err) == 2
    texts = {p.read_text().strip().splitlines()[-1] for p in saved}
    assert texts == {"ZeroDivisionError: boom first", "ZeroDivisionError: boom second"}
    assert all(str(p) in "\n".join(err) for p in saved)


# --------------------------------------------------------------------------------------- JSON inputs


def test_a_binary_meta_json_or_calibration_file_is_exit_3_naming_it_and_one_with_a_bom_is_read(tmp_path, capsys):
    run = _run_folder(tmp_path, smooth())
    (run / "meta.json").write_bytes(b"\xff\xfe{\x00}\x00\x80")
    assert main(["serv", str(run), "--no-history"]) == ExitCode.INPUT
    assert f"{run / 'meta.json'}: not " in _err(capsys)
    (run / "meta.json").unlink()
    cal = tmp_path / "result.json"
    cal.write_bytes(b"\x80\x81 binary")
    p = run / "signals.csv"
    assert main(["serv", str(p), "--calibration", str(cal), "--out", str(tmp_path / "o")]) == ExitCode.INPUT
    assert f"{cal}: not a JSON text file (byte 0 is not UTF-8)" in _err(capsys)
    assert not (tmp_path / "o").exists()
    doc = {"status": "pass", "calibration": {"ema1": {"pitch": 1.0, "offset_mm": 0.0},
                                             "ema2": {"pitch": 1.0, "offset_mm": 0.0}}}
    cal.write_bytes(codecs.BOM_UTF8 + json.dumps(doc).encode())
    rc = main(["serv", str(p), "--calibration", str(cal), "--out", str(tmp_path / "o"), "--no-report",
               "--no-history"])
    assert rc in (ExitCode.PASS, ExitCode.INCONCLUSIVE), _err(capsys)
    got = json.loads((tmp_path / "o" / "serv.json").read_text())["calibration"]
    assert got["source"].startswith("--calibration") and got["ema1"]["pitch"] == 1.0


@pytest.mark.parametrize("which,code", [("recording", ExitCode.INPUT), ("signals", ExitCode.INPUT),
                                        ("output", ExitCode.INTERNAL)])
def test_an_os_error_escaping_a_reader_is_exit_3_only_for_an_input_file(monkeypatch, capsys, tmp_path, which, code):
    """The readers name their errors themselves; main()'s net takes an OSError about a file the command
    was given (or a run folder's file in it) as bad input, any other (an output's) as internal."""
    import errno

    import hil.cli.analyze as cmd

    run = tmp_path / "run"
    failed = {"recording": run, "signals": run / "signals.csv", "output": run / "analysis-x" / "result.json"}[which]

    def unreadable(args):
        raise PermissionError(errno.EACCES, "Permission denied", str(failed))

    monkeypatch.setattr(cmd, "cmd_analyze", unreadable)
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    assert main(["analyze", str(run)]) == code
    err = _err(capsys)
    if code == ExitCode.INPUT:
        assert err == f"emacheck: error: {failed}: cannot be read: Permission denied\n"
    else:
        assert err.startswith("emacheck: internal error: PermissionError:")


def test_a_noise_free_d_is_exit_3_in_words_a_user_can_act_on(tmp_path, capsys):
    """s1 written as phi1 / i exactly: D_int1 has no noise, which BLFserv's thresholds need; the message
    says which D and why, not the API's "pass noise_std_mm explicitly" (an option no command has)."""
    a = smooth()
    a[:, 3] = a[:, 1] / 5.0265
    p = tmp_path / "computed.csv"
    np.savetxt(p, a, delimiter=",", header=HEADER, comments="", fmt=["%.4f"] + ["%.9f"] * 4 + ["%.3f"] * 2)
    assert main(["serv", str(p), "--out", str(tmp_path / "o"), "--no-history"]) == ExitCode.INPUT
    err = _err(capsys)
    assert err == (f"emacheck: error: {p}: D_int1 = s1 - phi1 / i holds no measurement noise (below 1e-6 mm): the "
                   "LVDT or motor angle is not a raw measurement (computed from the other, or smoothed); BLFserv "
                   "needs the recorded signals\n")
    assert not (tmp_path / "o").exists()


def test_an_aborted_runs_jump_is_what_stopped_it_not_bad_input(tmp_path, capsys):
    """An LVDT spike stops a check (the supervisor): the aborted run's folder holds that jump and is analysed
    as aborted (exit 2, what it holds), not refused; the same recording on its own is refused."""
    a = smooth()
    a[1500:, 3] += 0.5
    run = _run_folder(tmp_path, a)
    (run / "meta.json").write_text(json.dumps({"status": "aborted", "reason": "LVDT 1 spike"}))
    assert main(["analyze", str(run), "--out", str(tmp_path / "o"), "--no-history"]) == ExitCode.ABORTED
    res = json.loads((tmp_path / "o" / "result.json").read_text())
    assert res["status"] == "aborted" and res["reason"] == "LVDT 1 spike" and "jump" not in res["analysis_error"]
    (run / "meta.json").unlink()
    assert main(["analyze", str(run), "--out", str(tmp_path / "o2"), "--no-history"]) == ExitCode.INPUT
    assert f"{run / 'signals.csv'}: line 1502: a jump in position" in _err(capsys)


def test_an_eds_whose_pdo_mapping_count_is_absurd_is_checked_at_once(tmp_path, capsys):
    """A mapping record's sub-index 0 default of 0x80000181 (found by test_plan_fuzz): the planner reads at
    most the 64 entries CiA 301 allows instead of looping two billion times; profile check answers."""
    import time

    text = default_eds_path().read_text()
    head = "[1A00sub0]"
    i = text.index(head)
    j = text.index("DefaultValue=", i)
    k = text.index("\n", j)
    e = tmp_path / "drive.eds"
    e.write_text(text[:j] + "DefaultValue=0x80000181" + text[k:])
    t0 = time.perf_counter()
    rc = main(["profile", "check", str(default_profile_path("actuation.toml")), "--eds", str(e)])
    assert rc in (ExitCode.PASS, ExitCode.INPUT) and time.perf_counter() - t0 < 30
    assert "Traceback" not in capsys.readouterr().err
