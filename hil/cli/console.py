"""The terminal of a command: the console (rich), a running check's progress, the result table and what
the drives were left doing.
"""

from __future__ import annotations

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


def styled(text: str, status: str, bold: bool = False) -> str:
    """``text`` in the console colour of a verdict or run status (plain when it has none)."""
    style = (("bold " if bold else "") + _STATUS_STYLE.get(status, "")).strip()
    return f"[{style}]{text}[/]" if style else text


def print_summary(console: Console, result: dict, out_dir: Path | None) -> None:
    """The result as a table: per channel the decision against its limit with the expanded
    uncertainty and the margin, then stiffness; truth beside it when known."""
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
    if out_dir is not None:
        console.print(f"written to: {out_dir}")


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
