"""The force-free jog against a wrong gear ratio, for docs/commission.md (not a test:
``python tests/bench/bench_commission_jog.py``).

Commissions, in process, the simulated rig of the shipped profiles (its gear ratio 5.0265 rad/mm) with an
actuation profile whose ``mechanics.i_total_rad_per_mm`` is the rig's times each factor (no gear-ratio
object in the drives), and prints per factor: the exit status, the stage and key of the first finding, the
factor it names and the value that fits, the jog's largest load-cell change from rest and the plant's largest
true force over the whole run (the commissioning's force limit is 2000 N), and the wall time.
"""

from __future__ import annotations

import math
import sys
import tempfile
import time
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]  # the repository (hil, blf, sim) and tests/ (support)

import numpy as np  # noqa: E402

from hil.canopen.od import load_eds  # noqa: E402
from hil.cli.check import master_setup  # noqa: E402
from hil.cli.commission import commission  # noqa: E402
from hil.profile.load import load_actuation, load_check, load_simrig  # noqa: E402
from hil.transport import InProcessTransport  # noqa: E402
from sim.drives import SimDrivePair  # noqa: E402
from sim.faults import FaultInjector  # noqa: E402
from sim.plant import RigPlant  # noqa: E402
from support.profiles import write_profile_variant  # noqa: E402

FACTORS = (("degrees for radians", 180.0 / math.pi), ("revolutions for radians", 1.0 / (2.0 * math.pi)),
           ("x 1.25", 1.25), ("x 1.10", 1.10), ("right", 1.0))


def main() -> None:
    act0 = load_actuation(None)
    check = load_check(None, act0)
    simrig = load_simrig(None)
    true_rig = master_setup(act0, None)
    print("| profile's gear ratio | exit | first finding | factor named | fits [rad/mm] | jog: largest load-cell "
          "change [N] | largest true force [N] | wall [s] |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for name, factor in FACTORS:
            base = Path(tmp) / name.replace(" ", "_")
            base.mkdir()
            prof = write_profile_variant("actuation.toml", base / "a.toml", {
                "mechanics": {"i_total_rad_per_mm": act0.mechanics.i_total_rad_per_mm * factor},
                "canopen": {"gear_ratio_object": ""}})
            act = load_actuation(prof)
            rng = np.random.default_rng(simrig.seed)
            pair = SimDrivePair(RigPlant(simrig.params, rng), true_rig.plan,
                                lambda n, node_id: load_eds(true_rig.eds_paths[n], node_id=node_id),
                                serials=simrig.serials)
            inj = FaultInjector(pair, (), rng=np.random.default_rng([simrig.seed, 7]), record_truth=True)
            (base / "out").mkdir()
            t0 = time.perf_counter()
            run = commission(act, check, master_setup(act, prof), InProcessTransport(inj, act.timing.sync_period_s),
                             base / "out")
            wall = time.perf_counter() - t0
            f = run.report["findings"]
            first = f"{f[0]['stage']}: {f[0]['kind']} {f[0]['key']}" if f else "- (ready)"
            named = f"{f[0]['measured']:.4g}" if f and f[0]["measured"] is not None else "-"
            fits = f[0]["fits"] if f else "-"
            jog = run.core.jog.peak_force_change_N() if run.core.jog else math.nan
            print(f"| {name} (x {factor:.4g}) | {run.exit_code} | {first} | {named} | {fits} | {jog:.0f} | "
                  f"{np.max(np.abs(inj.truth.F_N)):.0f} | {wall:.1f} |")


if __name__ == "__main__":
    main()
