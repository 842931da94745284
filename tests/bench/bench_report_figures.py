"""Benchmark (not a test): the maintenance report's drawing time, in process, on a dry-run's folder.

Reads a run folder (``emacheck dry-run --out DIR``), analyses it once (not timed), then draws the report
(:func:`hil.report.maint.report_html`) ``--repeat`` times, each in one process (``drawn``'s fork off) and
in two (as the command draws it), and prints the medians of the CPU time (this process's
``time.process_time``; the fork's is not in it) and wall time, and each figure's own CPU time in one
process, drawn as the report draws it (:func:`hil.report.shell.img`: laid out once at 90 dpi) and, in
turn with it (a shared machine's load falls on both alike), as it was drawn until 2026-11-27
(``Figure.tight_layout`` at the figure's 100 dpi, then ``savefig(bbox_inches="tight")`` at 90 dpi).
``--png DIR`` writes the figures of the last drawing as PNG files (figure-0.png, ...), to look at them
beside another tree's.

Usage: PYTHONPATH=$PWD python tests/bench/bench_report_figures.py RUN_DIR [--repeat 5] [--png DIR]
"""

from __future__ import annotations

import argparse
import base64
import io
import re
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))  # the repository (hil, blf, sim)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--png", type=Path, default=None)
    args = ap.parse_args(argv)

    import hil.report.maint as rm
    import hil.report.shell as shell
    from hil.cli.result import analysed
    from hil.record.recording import actuation_for
    from hil.record.runfolder import read_record

    meta = read_record(args.run_dir)
    act = actuation_for(None, meta)
    sig, an, result = analysed(args.run_dir / "signals.csv", act, meta.truth, meta)
    shell.pyplot()
    rm.report_html(sig, an, result, act, meta)  # warm: fonts, mathtext, first-use caches

    drawn = shell.drawn
    out: dict[str, tuple[float, float]] = {}
    html = ""
    for processes in (1, 2):
        rm.drawn = lambda parts, processes=processes: drawn(parts, processes=processes)
        cpu, wall = [], []
        for _ in range(args.repeat):
            c, w = time.process_time(), time.perf_counter()
            html = rm.report_html(sig, an, result, act, meta)
            cpu.append(time.process_time() - c)
            wall.append(time.perf_counter() - w)
        out[f"{processes} process{'es' if processes > 1 else ''}"] = (statistics.median(cpu),
                                                                      statistics.median(wall))
    rm.drawn = drawn
    for k, (c, w) in out.items():
        print(f"report_html, {k}: CPU {c:.3f} s, wall {w:.3f} s (median of {args.repeat})")

    names = {"time": lambda: rm.figure_time(sig, an, act), "calibration": lambda: rm.figure_calibration(sig, an, act)}
    if meta.timing is not None:
        names["timing"] = lambda: rm.figure_timing(meta.timing)
    for ch in ("int1", "ext"):
        d, f = rm._channel_data(sig, an, ch)
        r = an.maint[ch]
        names[f"dfdd {ch}"] = lambda ch=ch, d=d, f=f, r=r: rm.figure_dfdd(ch, d, f, r)
        names[f"lines {ch}"] = lambda ch=ch, d=d, f=f, r=r: rm.figure_lines(ch, d, f, r, result.get("truth"))
    def old_style(fig) -> bytes:
        buf = io.BytesIO()
        fig.tight_layout()
        fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
        shell.pyplot().close(fig)
        return buf.getvalue()

    total = {"now": 0.0, "before": 0.0}
    for name, make in names.items():
        cpu: dict[str, list[float]] = {"now": [], "before": []}
        for _ in range(args.repeat):
            for style, draw in (("now", lambda fig: shell.img(fig, dpi=90)), ("before", old_style)):
                fig = make()  # (built outside the timing: the same in both)
                c = time.process_time()
                draw(fig)
                cpu[style].append(time.process_time() - c)
        med = {k: statistics.median(v) for k, v in cpu.items()}
        for k in total:
            total[k] += med[k]
        print(f"  figure {name}: laid out and drawn, CPU {med['now']:.3f} s (before: {med['before']:.3f} s)")
    print(f"  all: CPU {total['now']:.3f} s (before: {total['before']:.3f} s, "
          f"{100 * (total['now'] / total['before'] - 1):+.0f} %)")

    if args.png is not None:
        args.png.mkdir(parents=True, exist_ok=True)
        for i, uri in enumerate(re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", html)):
            (args.png / f"figure-{i}.png").write_bytes(base64.b64decode(uri))
        print(f"PNGs written to {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
