"""A simulated scenario recording is three parts simulated one after the other (two calibration sweeps,
then the scenario), each from its own start: its run record says so (mode simulate-scenario), and the
jump rule judges each part on its own. The same signals without that record are a joined recording."""

from __future__ import annotations

import shutil

import pytest

from hil.cli import main

pytestmark = pytest.mark.slow


def test_serv_reads_a_scenario_record_but_refuses_its_signals_alone(tmp_path, capsys):
    rec = tmp_path / "rec"
    assert main(["simulate", "--scenario", "small-manoeuvres", "--out", str(rec)]) == 0
    assert main(["serv", str(rec), "--out", str(tmp_path / "serv")]) in (0, 1, 5)
    bare = tmp_path / "bare.csv"
    shutil.copy(rec / "signals.csv", bare)
    capsys.readouterr()
    assert main(["serv", str(bare), "--calibration", str(tmp_path / "serv" / "serv.json"),
                 "--out", str(tmp_path / "serv2")]) == 3
    err = capsys.readouterr().err
    assert f"{bare}: line " in err and "a jump in position" in err
