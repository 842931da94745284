"""Screenshot of the dual-EMA reference report (not a test; docs/diagnose.md shows it):
``python tests/bench/make_diagnose_reference_screenshot.py``.

Two simulated checks of the shipped rig (``emacheck simulate``): healthy with noise seed 11, and with the load cell
gain of EMA 2 up 2 % (seed 13); ``emacheck diagnose CHANGED --reference HEALTHY``; its diagnosis_report.html
cut to its first 1700 pixels. Needs headless Chromium and Pillow (as tests/bench/make_report_screenshots.py,
whose helpers it uses). Writes docs/img/diagnose-reference.png (``--out`` to choose).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]

from bench.make_report_screenshots import chromium, small_png  # noqa: E402
from hil.cli import main  # noqa: E402
from support.profiles import write_profile_variant  # noqa: E402


def main_(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=TESTS.parent / "docs" / "img" / "diagnose-reference.png")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        rig = write_profile_variant("simrig.toml", work / "rig.toml", {"sensors2": {"loadcell_gain": 1.02}})
        for argv_ in (["--seed", "11", "--out", str(work / "healthy")],
                      ["--sim", str(rig), "--seed", "13", "--out", str(work / "changed")]):
            if main(["simulate", "--quiet", *argv_]) != 0:
                raise SystemExit(f"simulate {argv_} failed")
        if main(["diagnose", str(work / "changed"), "--reference", str(work / "healthy"), "--out",
                 str(work / "diag"), "--quiet"]) != 0:
            raise SystemExit("diagnose failed")
        shot = work / "shot.png"
        chromium((work / "diag" / "diagnosis_report.html").as_uri(), f"--screenshot={shot}", "--window-size=1300,2600")
        small_png(shot, args.out, width=1000, height=1700)
    print(f"written {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main_())
