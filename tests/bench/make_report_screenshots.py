"""Screenshots of a PASS, a FAIL and an INCONCLUSIVE maintenance report, and one printed to PDF (not a test:
``python tests/bench/make_report_screenshots.py``; docs/report.md shows the images).

Each report is a real ``emacheck dry-run`` (the check over CANopen against the simulated drives, so every
report says SIMULATED) with the shipped profiles, except the simulated rig:

* PASS: the shipped rig (internal backlash 0.10 / 0.12 mm, B_spec 0.2 mm);
* FAIL: EMA 1 worn to 0.25 mm internal backlash: B - U > B_spec;
* INCONCLUSIVE: EMA 2 worn to 0.196 mm: B_spec = 0.2 mm lies within B ± U.

Needs headless Chromium (Debian: ``apt-get install chromium``) and, for the printed page, pdftoppm
(``poppler-utils``); the PNGs are cut to the report's first screen and reduced to a palette (Pillow) to stay
small. Writes docs/img/report-{pass,fail,inconclusive}.png, docs/img/report-print-page1.png and
docs/img/report-print-page3.png (``--out`` to choose), and the run folders into a temporary folder (``--keep``
to keep them).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]  # the repository (hil, blf, sim) and tests/ (support)

from hil.cli import main  # noqa: E402
from support.profiles import write_profile_variant  # noqa: E402

CASES = {  # name -> (simulated-rig overrides, expected exit status)
    "pass": ({}, 0),
    "fail": ({"ema1": {"backlash_int_mm": 0.25}}, 1),
    "inconclusive": ({"ema2": {"backlash_int_mm": 0.196}}, 5),
}
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync",
                  "--hide-scrollbars"]


def chromium(url: str, *args: str) -> None:
    """One headless Chromium call with its own throw-away profile."""
    exe = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    if exe is None:
        raise SystemExit("no chromium on PATH (Debian: apt-get install chromium)")
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", *args, url], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120)


def small_png(src: Path, dst: Path, *, width: int, height: int | None = None) -> None:
    """``src`` cut to ``height`` pixels (None: all), scaled to ``width``, as a 256-colour PNG."""
    from PIL import Image

    im = Image.open(src).convert("RGB")
    if height is not None:
        im = im.crop((0, 0, im.width, min(height, im.height)))
    if im.width != width:
        im = im.resize((width, round(im.height * width / im.width)), Image.LANCZOS)
    im.quantize(colors=256, method=Image.Quantize.MEDIANCUT).save(dst, optimize=True)


def make_run(work: Path, name: str, overrides: dict, expected: int) -> Path:
    """A dry-run with the simulated rig ``overrides``; its report.html."""
    sim = write_profile_variant("simrig.toml", work / f"simrig-{name}.toml", overrides) if overrides else None
    out = work / name
    argv = ["dry-run", "--quiet", "--out", str(out), "--operator", "A. Inspector", "--work-order", "WO-4711",
            "--aircraft", "D-EMAX", "--position", "left aileron", "--flight-hours", "4150"]
    rc = main(argv + (["--sim", str(sim)] if sim else []))
    if rc != expected:
        raise SystemExit(f"{name}: dry-run exited {rc}, expected {expected}")
    return out / "report.html"


def main_(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=TESTS.parent / "docs" / "img", help="where the PNGs go")
    ap.add_argument("--keep", action="store_true", help="keep the run folders (printed)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="emacheck-screenshots-"))
    try:
        for name, (overrides, expected) in CASES.items():
            report = make_run(work, name, overrides, expected)
            raw = work / f"{name}-raw.png"
            chromium(report.as_uri(), f"--screenshot={raw}", "--window-size=1200,1900")
            small_png(raw, args.out / f"report-{name}.png", width=900)
            print(args.out / f"report-{name}.png", (args.out / f"report-{name}.png").stat().st_size, "bytes")
            if name == "inconclusive":  # printed: A4 pages, figures whole
                pdf = work / f"{name}.pdf"
                chromium(report.as_uri(), f"--print-to-pdf={pdf}", "--no-pdf-header-footer")
                subprocess.run(["pdftoppm", "-png", "-r", "60", str(pdf), str(work / "page")], check=True)
                pages = sorted(work.glob("page-*.png"))
                print(pdf, len(pages), "A4 pages")
                for k in (1, 3):
                    if k <= len(pages):
                        small_png(pages[k - 1], args.out / f"report-print-page{k}.png", width=500)
                        print(args.out / f"report-print-page{k}.png")
    finally:
        if args.keep:
            print("run folders in", work)
        else:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main_())
