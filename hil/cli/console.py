"""The terminal of a command: the console (rich), a running check's progress, the result table and what
the drives were left doing.
"""

from __future__ import annotations

import collections
from pathlib import Path

from rich import box
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from blf.signals import CHANNELS
from hil.record.runrecord import RunRecord


def make_console(**kwargs):
    """The terminal of a command (rich); 120 columns when the output is a file or a pipe, so that the
    result table is not folded in a log."""
    import sys

    from rich.console import Console

    if not sys.stdout.isatty():
        kwargs.setdefault("width", 120)
    return Console(**kwargs)


class LiveProgress:
    """Terminal progress of a running check: step, progress, forces and strokes."""

    def __init__(self, console: Console, total_s: float, enabled: bool) -> None:
        self.enabled = enabled and console.is_terminal
        self._p = Progress(TextColumn("[bold]{task.fields[step]:<12}"), BarColumn(),
                           TextColumn("{task.percentage:>3.0f}%"), TextColumn("{task.fields[values]}"),
                           TimeElapsedColumn(), console=console, transient=False, disable=not self.enabled,
                           refresh_per_second=8)
        self._task = self._p.add_task("check", total=1.0, step="", values="")
        self._n = 0

    def __enter__(self) -> LiveProgress:
        self._p.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self._p.__exit__(*exc)

    def __call__(self, prog, smp) -> None:
        self._n += 1
        if not self.enabled or self._n % 25:
            return
        vals = (f"F1 {smp.F1_N / 1e3:+6.2f} kN  F2 {smp.F2_N / 1e3:+6.2f} kN  "
                f"s1 {smp.s1_mm:+7.3f} mm  s2 {smp.s2_mm:+7.3f} mm  t {smp.t_s:6.1f} s")
        self._p.update(self._task, completed=prog.total_fraction, step=prog.step.value, values=vals)


class LogProgress:
    """Progress of a running check where the output is a log or a pipe (no terminal): a line at each step and
    every :data:`LOG_EVERY_S` seconds, with the time elapsed, the step and the check's time.

    The check loop only notes where it stands (one assignment per cycle, no IO on its thread); a thread of
    this object's own prints, so a slow pipe or disk never holds the loop."""

    def __init__(self, console: Console, every_s: float | None = None, clock=None) -> None:
        import threading
        import time

        self.enabled = True
        self._console = console
        self._every_s = LOG_EVERY_S if every_s is None else every_s
        self._clock = clock or time.monotonic
        self._latest: tuple | None = None  #: (step, fraction of the check, check time s), from the loop
        self._entered: collections.deque = collections.deque()  #: each step as the loop entered it
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="emacheck-progress", daemon=True)
        self._t0 = self._clock()

    def __enter__(self) -> LogProgress:
        self._t0 = self._clock()
        self._console.print("check started")
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        while self._entered:  # steps entered since the thread last looked
            self._console.print(self.line(self._entered.popleft()), highlight=False)

    def __call__(self, prog, smp) -> None:
        latest = (prog.step.value, prog.total_fraction, smp.t_s)  # the loop's only work here: a note
        if self._latest is None or latest[0] != self._latest[0]:
            self._entered.append((*latest, self._clock()))  # (a deque's append: no lock, no IO)
        self._latest = latest

    def line(self, latest: tuple) -> str:
        """One progress line of ``latest`` (step, fraction, check time s[, clock when noted])."""
        step, frac, t_s, *at = latest
        return (f"[{(at[0] if at else self._clock()) - self._t0:7.1f} s] {step} ({100.0 * frac:3.0f} % of the "
                f"check, check time {t_s:.1f} s)")

    def _run(self) -> None:
        shown_at = self._clock()
        while not self._stop.wait(0.2):
            now = self._clock()
            if self._entered:
                while self._entered:
                    self._console.print(self.line(self._entered.popleft()), highlight=False)
                shown_at = now
            elif self._latest is not None and now - shown_at >= self._every_s:
                self._console.print(self.line(self._latest), highlight=False)
                shown_at = now


#: a running check's progress line, where the output is no terminal, at least this often [s]
LOG_EVERY_S = 10.0


def check_progress(console: Console, quiet: bool):
    """The progress display of a running check: live on a terminal (:class:`LiveProgress`), lines in a log or
    a pipe (:class:`LogProgress`), none with ``--quiet``."""
    if console.is_terminal or quiet:
        return LiveProgress(console, 0.0, not quiet)
    return LogProgress(console)


def styled(text: str, status: str, bold: bool = False) -> str:
    """``text`` in the console colour of a verdict or run status (plain when it has none)."""
    style = (("bold " if bold else "") + _STATUS_STYLE.get(status, "")).strip()
    return f"[{style}]{text}[/]" if style else text


def print_summary(console: Console, result: dict, report: Path | None) -> None:
    """The result as a table: per channel the decision against its limit with the expanded
    uncertainty and the margin, then stiffness; truth beside it when known; last, the report to open
    (``report``, its result.json beside it)."""
    truth = result.get("truth")
    status = result["status"]
    tab = Table(title=f"BLFmaint result: {styled(status.upper(), status, bold=True)}",
                box=box.SIMPLE_HEAD, pad_edge=False)
    for col, just in (("channel", "left"), ("backlash ± U mm", "right"), ("limit mm", "right"),
                      ("margin mm", "right"), ("verdict", "left"), ("c_l / c_r kN/mm", "right")):
        tab.add_column(col, justify=just)
    if truth:
        tab.add_column("truth B mm", justify="right")
        tab.add_column("truth c kN/mm", justify="right")
    verdict = result.get("verdict", {})
    kn = lambda x: "—" if x is None else f"{x / 1e3:.1f}"  # noqa: E731
    for ch in CHANNELS:
        b = result["backlash_mm"][ch]
        v = verdict.get(ch, {})
        st = v.get("status", "")
        u = v.get("uncertainty_mm")
        stf = result["stiffness_N_per_mm"][ch]
        row = [ch, "—" if b is None else f"{b:.4f}" + ("" if u is None else f" ± {u:.4f}"),
               "—" if v.get("limit_mm") is None else f"{v['limit_mm']:.3f}",
               "—" if v.get("margin_mm") is None else f"{v['margin_mm']:+.4f}",
               styled(st, st) if st else "—",
               f"{kn(stf['left'])} / {kn(stf['right'])}"]
        if truth:
            ts = truth["stiffness_N_per_mm"][ch]
            row += [f"{truth['backlash_mm'][ch]:.4f}", f"{kn(ts['left'])} / {kn(ts['right'])}"]
        tab.add_row(*row)
    console.print(tab)
    for ch in CHANNELS:
        v = verdict.get(ch, {})
        if v.get("status") not in (None, "pass"):
            console.print(f"{ch}: {v['status']}: {v['reason']}")
    for k in ("ema1", "ema2"):
        c = result["calibration"][k]
        if c is None:
            console.print(f"LVDT {k[-1]}: not calibrated (no sweep)")
        else:
            tr = truth["calibration"][k]["pitch"] if truth else None
            console.print(f"LVDT {k[-1]}: pitch {c['pitch']:.5f}" + (f" (truth {tr:.5f})" if tr else "")
                          + f", offset {c['offset_mm']:+.4f} mm, rmse {c['rmse_mm']:.4f} mm")
    for n in result.get("notes", []):
        console.print(f"[yellow]note:[/yellow] {n}")
    if result.get("reason"):
        console.print(f"[red]{status}:[/red] {result['reason']}")
    if report is not None:
        console.print(f"written to: {report.parent}; open [bold]{report}[/bold] to read and sign the result"
                      if report.exists() else f"written to: {report.parent}", soft_wrap=True)


def print_drives_final(console: Console, meta: RunRecord) -> None:
    """Each drive's CiA 402 state after the check as it was seen (meta.json ``drives_final``)."""
    for ema, d in (meta.drives_final or {}).items():
        safe = "safe" if d.safe else "[red]NOT confirmed safe[/red]"
        how = "" if d.reachable else ", unreachable (heartbeat lost)"
        state = d.state if d.state is not None else "state unknown"
        console.print(f"EMA {ema[-1]} (node {d.node}): {state}, {safe}{how}" + (f" ({d.seen})" if d.seen else ""))


def print_master_loss(console: Console, meta: RunRecord) -> None:
    """Each drive's reaction to the master's death as configured and as the drill saw it (meta.json
    ``master_loss``, the refusal's included), and the external watchdog where the profile states one."""
    from rich.markup import escape

    from hil.report.shell import master_loss_text

    for ema, ml in (meta.master_loss or {}).items():
        console.print(f"EMA {ema[-1]} reaction to losing the master: {escape(master_loss_text(ml))}")


_STATUS_STYLE = {"pass": "green", "fail": "red", "inconclusive": "yellow", "aborted": "red", "incomplete": "yellow"}
