"""``emacheck diagnose NEW --reference HEALTHY`` with the dual-EMA model (issue 35, part 1; first cut).

Slow (about 1 min): simulated checks of the shipped rig (``emacheck simulate``), healthy with noise seed 11
and changed with seed 13: the contact stiffness of EMA 1 down 20 %, the internal play of EMA 2 up 30 um.
Each change is named at the right EMA with the right sign and a size within 30 %. Extras are not asserted
(docs/diagnose.md says which appear).
"""

from __future__ import annotations

import json

import jsonschema
import pytest

from hil.cli import main
from support.profiles import write_profile_variant

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def healthy(tmp_path_factory):
    out = tmp_path_factory.mktemp("dual") / "healthy"
    assert main(["simulate", "--seed", "11", "--out", str(out), "--quiet"]) == 0
    return out


@pytest.mark.parametrize("section, values, param, where, change", [
    ("ema1", {"stiffness_compression_N_per_mm": 64000.0, "stiffness_tension_N_per_mm": 64000.0},
     "stiffness_int1_N_per_mm", "ema1", -20.0),
    ("ema2", {"backlash_int_mm": 0.15}, "backlash_int2_mm", "ema2", 30.0),
])
def test_a_changed_rig_is_named_at_the_right_ema_with_sign_and_size(healthy, tmp_path, section, values, param,
                                                                     where, change):
    run = tmp_path / "changed"
    rig = write_profile_variant("simrig.toml", tmp_path / "rig.toml", {section: values})
    assert main(["simulate", "--sim", str(rig), "--seed", "13", "--out", str(run), "--quiet"]) == 0
    out = tmp_path / "o"
    assert main(["diagnose", str(run), "--reference", str(healthy), "--out", str(out), "--quiet"]) == 0
    data = json.loads((out / "diagnosis.json").read_text())
    from importlib import resources
    jsonschema.validate(data, json.loads(resources.files("hil.schemas").joinpath("diagnosis.schema.json").read_text()))
    (e,) = [e for e in data["effects"] if param in e["change"]]
    assert e["where"] == where
    assert e["change"][param] == pytest.approx(change, rel=0.3)
