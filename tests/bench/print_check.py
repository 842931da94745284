"""Print a report with headless Chromium and Firefox and say what each printed page carries (not a test:
``python tests/bench/print_check.py RUN/report.html``; docs/report.md, *Printing*, quotes its output).

Per browser and page: whether the running header and footer (the run id) are there, the page number printed
by the ``@page`` margin box ("page i of n"), and the first line of the page's content. Needs chromium,
firefox-esr and poppler-utils (Debian); a browser that is missing is said and skipped.
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(TESTS.parent), str(TESTS)]

from support import printing  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("report", type=Path, help="a report.html (serv_report.html, ...)")
    args = ap.parse_args()
    run = re.search(r"run ([0-9a-f]{32})", args.report.read_text())
    run_id = run.group(1) if run else None
    with tempfile.TemporaryDirectory() as tmp:
        for name, how in (("Chromium", printing.chromium_pdf), ("Firefox", printing.firefox_pdf)):
            pdf = Path(tmp) / f"{name}.pdf"
            try:
                version = how(args.report, pdf) or name
            except printing.Missing as exc:
                print(f"{name}: {exc}")
                continue
            pages = printing.pages(pdf)
            print(f"{version}: {len(pages)} pages")
            for i, text in enumerate(pages, start=1):
                lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
                heads = sum(run_id in ln for ln in lines) if run_id else 0
                number = f"page {i} of {len(pages)}" in text
                body = next((ln for ln in lines if not run_id or run_id not in ln), "")
                print(f"  page {i}: run id {heads}x, page number {'yes' if number else 'no'}; {body[:60]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
