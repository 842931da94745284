"""The movements' figure of a commissioning report, for docs/commission.md (not a test:
``python tests/bench/make_commission_figure.py``).

Runs ``emacheck commission --simulate --wiring-fault lvdt_sign:2`` (the shipped profiles, the simulated rig
with EMA 2's LVDT wired with the wrong sign) into a temporary folder and writes the report's figure
(:func:`hil.report.commission.figure_movements`) to docs/img/commission-lvdt-sign.png (``--out`` to choose).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]  # the repository (hil, blf, sim) and tests/ (support)

from hil.cli.check import master_setup  # noqa: E402
from hil.cli.commission import commission  # noqa: E402
from hil.cli.commission_setup import simulated_transport, wiring_fault  # noqa: E402
from hil.profile.load import load_actuation, load_check, load_simrig  # noqa: E402
from hil.report.commission import figure_movements  # noqa: E402
from hil.report.shell import laid_out  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=TESTS.parent / "docs" / "img" / "commission-lvdt-sign.png")
    args = ap.parse_args()
    act = load_actuation(None)
    check = load_check(None, act)
    rig = master_setup(act, None)
    with tempfile.TemporaryDirectory() as tmp:
        run = commission(act, check, rig, simulated_transport(act, rig, load_simrig(None),
                                                             (wiring_fault("lvdt_sign:2"),), None), Path(tmp))
    i = act.mechanics.i_total_rad_per_mm
    traces = {n: {**x, "x1": x["phi1"] / i, "x2": x["phi2"] / i} for n, x in run.core.traces.items()}
    fig = figure_movements(traces, act.timing.sync_period_s)
    laid_out(fig, 70).savefig(args.out, dpi=70)
    print(f"exit {run.exit_code}: {[f['key'] for f in run.report['findings']]}; wrote {args.out}")


if __name__ == "__main__":
    main()
