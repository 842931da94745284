"""``emacheck history``: every check of an actuator, its wear trend and when it reaches B_spec;
``emacheck history sync``: record results that could not be recorded when they were made."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from hil.cli.args import EPILOG, ExitCode, add_parser, history_url_type, identity_text
from hil.cli.console import make_console
from hil.cli.history_glue import history_url_for
from hil.record.outputs import fresh_outputs


def _serial(text: str) -> int:
    try:
        v = int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a serial number: {text!r} (decimal, or hex as 0x5E000101)") from None
    if not 0 <= v <= 0xFFFF_FFFF:
        raise argparse.ArgumentTypeError(f"{text}: a 0x1018 serial number is 0..0xFFFFFFFF")
    return v


def cmd_history(args: argparse.Namespace) -> int:
    """``emacheck history [--history URL] [--actuator SERIAL] [--aircraft REG] [--json] [--out DIR]``."""
    from hil.history.store import HistoryStore
    from hil.history.trends import build_series, history_document
    from hil.profile.history_url import masked

    url = history_url_for(args.history, args.profile)
    filters = {"actuator": args.actuator, "aircraft": args.aircraft}
    store = HistoryStore.open(url, create=False)
    if store is None:
        rows = []
    else:
        with store:
            rows = store.checks(serial=args.actuator, aircraft=args.aircraft)
    series = build_series(rows, serial=args.actuator)
    doc = history_document(rows, series, url=masked(url), filters=filters)
    outputs = None
    if args.out is not None:
        from hil.report.history import write_history_report

        outputs = fresh_outputs(args.out, "history")  # never over earlier files there
        outputs.write_json("history.json", doc)
        outputs.write_with("history.html", lambda p: write_history_report(p, doc, series, json_name="history.json"))
    if args.json:
        json.dump(doc, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return ExitCode.PASS
    console = make_console()
    print_history(console, doc, series, detail=bool(args.actuator is not None or args.aircraft or len(series) <= 12))
    if store is None:
        console.print(f"no checks recorded yet in {masked(url)}")
    if outputs is not None:
        console.print(f"history.html and history.json in {outputs.folder}")
    return ExitCode.PASS


def _interval(lo, hi, nd: int = 0, unit: str = "") -> str:
    def f(v) -> str:
        return "…" if v is None else (f"{v:.{nd}f}" if nd >= 0 else str(v))

    return f"{f(lo)}–{f(hi)}{unit}"


def print_history(console, doc: dict, series: list, *, detail: bool) -> None:
    """The history on the console: the trends table, then (``detail``) each series' checks."""
    from rich import box
    from rich.markup import escape
    from rich.table import Table

    from hil.history.trends import fmt_serial, iso

    trends = doc["trends"]
    groups: dict[tuple, list] = {}
    for t in trends:
        groups.setdefault((t["simulated"], t["aircraft"], t["position"]), []).append(t)
    old = sum(not c.get("current", True) for c in doc["checks"])
    console.print(f"[bold]Wear trends[/bold] in {escape(doc['history'])}: {len(doc['checks'])} result(s)"
                  + (f", {old} superseded by a later analysis of the same run (kept; the latest is current)"
                     if old else ""))
    for (sim, aircraft, position), ts in groups.items():
        where = ", ".join(x for x in (aircraft, position) if x) or "installation not recorded"
        tab = Table(title=escape(where + (" [simulated]" if sim else "")), title_justify="left",
                    box=box.SIMPLE_HEAD, pad_edge=False)
        for col, just in (("actuator", "left"), ("ch", "left"), ("trend", "left"), ("n", "right"),
                          ("rate ± σ", "right"), ("now\nmm", "right"), ("B_spec\nmm", "right"),
                          ("B_spec at\nFH (95 %)", "right"), ("date (UTC)\n(95 %)", "right")):
            tab.add_column(col, justify=just, no_wrap=True)
        notes = []
        for t in ts:
            who = fmt_serial(t["serial"]) if t["ema"] else "\n".join(fmt_serial(v) for v in t["pair"].values())
            rate = t["rate_mm_per_1000_fh"] if t["rate_mm_per_1000_fh"] is not None else t["rate_mm_per_year"]
            rs = "—" if rate is None else f"{rate:.4f} ± {t['rate_sigma']:.4f}\n{t['rate_unit']}"
            seg = f"{t['segment'] + 1}" + ("" if t["current"] else " old")
            lo, hi = t["limit_at_fh_interval"]
            dlo, dhi = t["limit_at_date_interval"]
            fh = ("—" if t["limit_at_fh"] is None else f"{t['limit_at_fh']:.0f}") + (
                "" if (lo, hi) == (None, None) else f"\n{_interval(lo, hi)}")
            date = (t["limit_at_date"] or "—") + (
                "" if (dlo, dhi) == (None, None) else f"\n{_interval(dlo, dhi, nd=-1)}")
            tab.add_row(who, t["channel"], seg, str(t["n"]), rs,
                        "—" if t["backlash_now_mm"] is None else f"{t['backlash_now_mm']:.4f}",
                        "—" if t["limit_mm"] is None else f"{t['limit_mm']:.3f}", fh, date)
            if t["reason"]:
                notes.append(f"{who.replace(chr(10), '/')} {t['channel']} (trend {seg}): {t['reason']}")
        console.print(tab)
        for n in notes:
            console.print(escape(n), soft_wrap=True)
    print_not_trended(console, doc, detail=detail)
    if not detail:
        console.print(f"{len(doc['checks'])} result(s); --actuator SERIAL or --aircraft REG lists the checks")
        return
    for s in series:
        t = Table(title=escape(s.title()), box=box.SIMPLE_HEAD, pad_edge=False, title_justify="left")
        for col in ("time (UTC)", "FH", "FC", "kind", "run", "backlash ± U mm", "verdict", "segment"):
            t.add_column(col, justify="left" if col in ("time (UTC)", "kind", "run", "verdict") else "right")
        pts = sorted(s.points + s.serv_points, key=lambda p: p.time)
        for p in pts:
            r = p.row
            u = "" if p.uncertainty_mm is None else f" ± {p.uncertainty_mm:.4f}"
            t.add_row(iso(r["time_utc"]), "—" if r["flight_hours"] is None else f"{r['flight_hours']:.0f}",
                      "—" if r["flight_cycles"] is None else str(r["flight_cycles"]), r["kind"],
                      (r["run_id"] or r["run_key"])[:8], f"{p.backlash_mm:.4f}{u}", p.verdict or "—",
                      str(p.segment + 1) if r["kind"] == "maint" else "(serv)")
        console.print(t)


def print_not_trended(console, doc: dict, *, detail: bool) -> None:
    """The results in no trend and why (their actuators' identity is unknown); with ``detail`` each one."""
    from rich.markup import escape

    from hil.history.trends import NO_IDENTITY

    out = [c for c in doc["checks"] if c.get("not_trended")]
    if not out:
        return
    console.print(escape(f"{len(out)} result(s) in no trend: {NO_IDENTITY}"), soft_wrap=True)
    for c in out if detail else ():
        read = ", ".join(f"{ch} {v:.4f}" for ch, v in c["backlash_mm"].items() if v is not None)
        console.print(escape(f"  {c['time_utc']} {c['kind']} {c['status']} ({read} mm) of "
                             f"{c.get('recording') or c['run_key']}: {c['not_trended']}"), soft_wrap=True)


def cmd_sync(args: argparse.Namespace) -> int:
    """``emacheck history sync RUN_FOLDER...``: record their results (each exactly once)."""
    from rich.markup import escape

    from hil.history.store import HistoryStore
    from hil.history.sync import sync
    from hil.profile.history_url import masked

    console = make_console()
    url = history_url_for(getattr(args, "sync_history", None) or args.history,
                          getattr(args, "sync_profile", None) or args.profile)
    with HistoryStore.open(url) as store:
        new, old = sync(store, args.folders, lambda m: console.print(escape(m), soft_wrap=True))
    console.print(f"{new} result(s) recorded, {old} already there, in {escape(masked(url))}")
    return ExitCode.PASS


def register(sub) -> None:
    p = add_parser(sub, "history", handler=cmd_history,
                   help="wear history: checks, trend and remaining life per actuator",
                   description="Every recorded check per actuator and channel, in order; the wear trend over "
                               "flight hours (calendar time where hours are missing), weighted by each reading's "
                               "uncertainty, with its band; the flight hours (and date) at which the backlash "
                               "reaches B_spec, with a 95 % interval. A step down (repair) or a new actuator at a "
                               "position starts a new trend. `emacheck history sync RUN_FOLDER...` records "
                               "results that could not be recorded when they were made.")
    p.add_argument("--history", metavar="URL", type=history_url_type,
                   help="the history database (default: the actuation profile's history.url, else the user's "
                        "SQLite file)")
    p.add_argument("--profile", metavar="ACTUATION.toml", type=Path,
                   help="actuation profile whose history.url to read (default: the shipped one)")
    p.add_argument("--actuator", metavar="SERIAL", type=_serial,
                   help="only this actuator (0x1018 serial number, decimal or 0x...)")
    p.add_argument("--aircraft", metavar="REG", type=identity_text,
                   help="only checks on this aircraft (at most 64 characters, as recorded)")
    p.add_argument("--json", action="store_true", help="print the history as JSON (checks and trends) instead")
    p.add_argument("--out", metavar="DIR", type=Path,
                   help="also write history.html (plots, tables) and history.json here")
    hs = p.add_subparsers(dest="history_cmd", metavar="sync", parser_class=type(p))
    s = hs.add_parser("sync", help="record run folders' results (each exactly once)",
                      description="Record the results of run folders (result.json, analysis-*/result.json, "
                                  "serv-*/serv.json) or result files in the history: those a database that was "
                                  "down or locked could not take. A result already recorded is not recorded again.",
                      epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    s.add_argument("folders", nargs="+", metavar="RUN_FOLDER", type=Path, help="run folders or result files")
    s.add_argument("--history", dest="sync_history", metavar="URL", type=history_url_type,
                   help="the history database (default: the profile's history.url, else the user's SQLite file)")
    s.add_argument("--profile", dest="sync_profile", metavar="ACTUATION.toml", type=Path,
                   help="actuation profile whose history.url to read")
    s.set_defaults(handler=cmd_sync)
