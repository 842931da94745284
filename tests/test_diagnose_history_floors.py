"""``emacheck diagnose RUN --reference history``: the floors measured from the wear history's healthy checks of
the same actuators (issue 48, part 4; docs/diagnose.md, "What a floor covers").

Slow (simulated checks of the shipped rig and their dual-EMA diagnoses): three healthy checks (noise seeds 11,
14, 15) recorded in a wear history, then a check with 10 N more Coulomb friction in the drive of EMA 1 (seed
13). Its reference is the last healthy check; the floors of every kind the three pairs of healthy checks
change are 3 x the RMS of those changes, labelled a reproducibility with the checks, the pairs and the changes.
With one healthy check in the history the floors stay the check profile's, labelled a repeatability.
"""

from __future__ import annotations

import json
from importlib import resources

import jsonschema
import numpy as np
import pytest

from hil.cli import main
from support.figures import figures_unrendered
from support.profiles import write_profile_variant
from support.shared_fits import module_fits_once  # noqa: F401 (a fixture, used below)

# the module's diagnoses read and fit each recording once (support.shared_fits): no recording here changes at its
# path, none is refused for itself
pytestmark = [pytest.mark.slow, pytest.mark.usefixtures("module_fits_once")]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("histfloors")
    healthy = [root / f"healthy{s}" for s in (11, 14, 15)]
    rig = write_profile_variant("simrig.toml", root / "later.toml", add={"effects": [
        {"name": "coulomb_friction", "where": "ema1", "force_N": 10.0}]})
    later = root / "later"
    with figures_unrendered():  # the simulated checks' reports are not read here: figures built, not drawn
        for seed, out in zip((11, 14, 15), healthy, strict=True):
            assert main(["simulate", "--seed", str(seed), "--out", str(out), "--quiet"]) == 0
        assert main(["simulate", "--sim", str(rig), "--seed", "13", "--out", str(later), "--quiet"]) == 0
    three, one = f"sqlite:///{root / 'three.db'}", f"sqlite:///{root / 'one.db'}"
    assert main(["history", "sync", *map(str, healthy), "--history", three]) == 0
    assert main(["history", "sync", str(healthy[0]), "--history", one]) == 0
    return {"healthy": healthy, "later": later, "three": three, "one": one}


def _diagnose(run, url, out):
    assert main(["diagnose", str(run), "--reference", "history", "--history", url, "--out", str(out), "--quiet",
                 "--no-report"]) == 0
    data = json.loads((out / "diagnosis.json").read_text())
    jsonschema.validate(data, json.loads(resources.files("hil.schemas").joinpath("diagnosis.schema.json").read_text()))
    return data


def test_the_history_s_healthy_checks_measure_the_floors_and_say_so(runs, tmp_path):
    data = _diagnose(runs["later"], runs["three"], tmp_path / "o")
    cov = data["floor"]["coverage"]
    assert cov["kind"] == "reproducibility" and cov["pairs"] == 3
    assert cov["references"] == [str(p.resolve()) for p in runs["healthy"]]
    assert data["reference_history"]["run_folder"] == str(runs["healthy"][-1].resolve())
    assert {"play_um", "stiffness_pct", "friction_N"} <= set(cov["measured"])
    for k in cov["measured"]:
        ch = np.asarray(cov["changes"][k])
        assert ch.size >= 3 and data["floor"]["by_kind"][k] == pytest.approx(3 * np.sqrt(np.mean(ch ** 2)), rel=1e-4)
    # a kind the pairs do not change keeps the profile's floor
    for k, v in data["floor"]["by_kind"].items():
        if k not in cov["measured"]:
            assert v == data["floor"]["defaults"][k]
    assert "measured from the wear history's healthy checks" in data["floor"]["source"]


def test_one_healthy_check_in_the_history_leaves_the_floors_a_repeatability(runs, tmp_path):
    data = _diagnose(runs["later"], runs["one"], tmp_path / "o")
    assert data["floor"]["coverage"]["kind"] == "repeatability"
    assert data["floor"]["by_kind"] == data["floor"]["defaults"]
