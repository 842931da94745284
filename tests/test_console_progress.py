"""The console of a check where the output is a log or a pipe (issue 47, part 6): a line when the check starts,
one at each step and one every 10 s, printed by a thread of its own (the loop only notes); the end names the
report to open."""

from __future__ import annotations

import threading
import types

import pytest

from hil.cli.console import LOG_EVERY_S, LogProgress, check_progress


class Console:
    """A console that keeps what it prints and on which thread."""

    is_terminal = False

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.threads: list[str] = []  #: the thread that printed each line

    def print(self, text, **_kw) -> None:
        self.lines.append(str(text))
        self.threads.append(threading.current_thread().name)


def _note(p: LogProgress, step: str, t_s: float, frac: float = 0.5) -> None:
    p(types.SimpleNamespace(step=types.SimpleNamespace(value=step), total_fraction=frac),
      types.SimpleNamespace(t_s=t_s))


def test_a_line_per_step_and_every_ten_seconds_printed_off_the_loop_thread():
    con, now = Console(), [100.0]
    clock = lambda: now[0]  # noqa: E731
    p = LogProgress(con, clock=clock)
    p._every_s = LOG_EVERY_S  # (as shipped: 10 s)
    with p:
        _note(p, "approach", 0.5, 0.0)
        for k in range(50):
            _note(p, "cal1_sweep", 2.0 + k)
        assert con.lines == ["check started"]  # the loop's calls print nothing themselves
        p._thread.join(0.5)
        assert [ln.split("] ")[1].split(" ")[0] for ln in con.lines[1:]] == ["approach", "cal1_sweep"]
        now[0] += LOG_EVERY_S - 0.5  # not yet 10 s since the last line
        p._thread.join(0.5)
        assert len(con.lines) == 3
        now[0] += 1.0  # 10.5 s: the periodic line, with the elapsed time and the check time
        p._thread.join(0.5)
        assert len(con.lines) == 4 and con.lines[-1].startswith("[   10.5 s] cal1_sweep") and "51.0 s" in con.lines[-1]
    assert con.threads[1:] == ["emacheck-progress"] * 3  # every progress line off the loop's thread


def test_steps_entered_after_the_thread_last_looked_are_printed_at_the_end():
    con = Console()
    with LogProgress(con, every_s=1e9) as p:
        _note(p, "force_fight", 80.0)
        _note(p, "unload", 111.0)
        _note(p, "done", 111.5, 1.0)
    assert [ln.split("] ")[1].split(" ")[0] for ln in con.lines[1:]] == ["force_fight", "unload", "done"]


def test_a_terminal_gets_the_live_display_a_pipe_the_lines_quiet_nothing():
    import io

    from rich.console import Console as RichConsole
    pipe, tty = RichConsole(file=io.StringIO()), RichConsole(file=io.StringIO(), force_terminal=True)
    assert isinstance(check_progress(pipe, quiet=False), LogProgress)
    assert not isinstance(check_progress(tty, quiet=False), LogProgress)
    assert not check_progress(pipe, quiet=True).enabled


@pytest.mark.slow
def test_a_piped_dry_run_says_each_step_and_names_the_report(tmp_path, capsys):
    """The whole dry-run with its output captured (no terminal): the steps in order, the report named."""
    from hil.cli import main
    assert main(["dry-run", "--out", str(tmp_path / "run")]) == 0
    out = capsys.readouterr().out
    steps = [ln.split("] ")[1].split(" ")[0] for ln in out.splitlines() if ln.startswith("[") and "] " in ln]
    assert steps[:3] == ["enable", "approach", "cal1_load"] and steps[-2:] == ["unload", "done"]
    assert "check started" in out and f"open {tmp_path / 'run' / 'report.html'} to read and sign" in out
