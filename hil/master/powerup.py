"""The CiA 402 power-up and power-down of one drive by its statusword, as a sans-IO core (issue 36).

:class:`PowerWalk` takes one drive to a goal of :class:`~hil.canopen.cia402.Goal` (ENABLED:
Operation enabled; DISABLED: Switch on disabled at once) command by command. It is fed each
statusword the caller read with the time it was received, and answers with a :class:`WalkStep`:
the controlwords to write now (in order), or done, or why it gives up. It never touches a bus or
a clock: the preflight's SDO walk (:meth:`hil.master.preflight.Preflight._walk`) drives it for the
master's-death drill, and commissioning is to drive it the same way (one implementation of the
rules, not a copy).

The rules (the commands themselves come from the one master table,
:func:`hil.canopen.cia402.master_command`):

* **Fresh statuswords only.** A statusword received at or before the time of the last
  controlword written (:meth:`PowerWalk.sent`) says nothing about that command and is not used
  (:attr:`WalkStep.stale`): every transition is confirmed by a statusword received after it.
* **Not ready to switch on**: disable voltage (0x0000) once, harmless there (the drive processes
  no command while it initialises), since some drives leave it only when a first controlword
  arrived (a CiA 402 slave on lely-core); then wait, bounded by the timeout.
* **Fault**: a fault reset on the rising edge of bit 7 (0x0000 first when the word before had it
  set), at most ``fault_reset_attempts`` of them. **Fault reaction active**: wait.
* **Quick stop active**: disable voltage (transition 12). A drive walked by SDO is at standstill
  (no SYNC runs; the drill's drive holds its position), so the master does not wait for the ramp
  as the cyclic phase does; transition 16 is never used.
* **Bounded**: past ``t0 + timeout_s`` the walk gives up, naming what it saw last and when.

:class:`StopConfirmation` is the end of a safe stop: after the last command, each drive's statusword
is read again by SDO (0x6041, bounded by the SDO timeout), so that "confirmed safe" means a state
observed after that command; a read that times out or is aborted leaves the drive not confirmed and
says why. :func:`final_state` words what the master saw of a drive ("stale since t = ...", "never
read"), for the run record and the abort reason.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from hil.canopen.cia402 import (
    SAFE_STATES,
    Command,
    Controlword,
    Goal,
    State,
    controlword,
    decode_state,
    master_command,
)
from hil.canopen.frame import Frame
from hil.canopen.sdo import SdoAbortError, SdoClient, SdoEvent, SdoTimeout, describe

__all__ = ["CONFIRM_READS", "Confirmed", "PowerWalk", "StopConfirmation", "WalkStep", "final_state"]

#: the state each goal a walk may have ends in
_TARGET = {Goal.ENABLED: State.OPERATION_ENABLED, Goal.DISABLED: State.SWITCH_ON_DISABLED}
_DV = controlword(Command.DISABLE_VOLTAGE)
_RESET = controlword(Command.FAULT_RESET)


@dataclass(frozen=True, slots=True)
class WalkStep:
    """What the walk asks for after a statusword.

    Attributes
    ----------
    controlwords : tuple of int
        Write these, in order, then call :meth:`PowerWalk.sent` with the time and read the
        statusword again (empty: read it again only).
    what : str
        The command the words carry (for messages), "" when none.
    done : bool
        The drive is in the goal's state, seen in a fresh statusword.
    failed : str
        Why the walk gave up ("" while it goes on); the caller raises it as its error.
    in_fault : bool
        It gave up in FAULT (the caller may add the drive's error code 0x603F).
    stale : bool
        The statusword was read before the last command: not used (read again).
    """

    controlwords: tuple[int, ...] = ()
    what: str = ""
    done: bool = False
    failed: str = ""
    in_fault: bool = False
    stale: bool = False


class PowerWalk:
    """One drive's walk to ``goal`` (see the module docstring).

    Parameters
    ----------
    label : str
        The drive as messages name it (``node 1 (EMA 1)``).
    goal : Goal
        ENABLED or DISABLED.
    t0_s : float
        When the walk starts [s, the caller's clock].
    timeout_s : float
        How long it may take [s] (``canopen.enable_timeout_s``, named in the message).
    fault_reset_attempts : int
        Fault resets allowed (``canopen.fault_reset_attempts``).
    """

    def __init__(self, label: str, goal: Goal, t0_s: float, timeout_s: float, fault_reset_attempts: int) -> None:
        if goal not in _TARGET:
            raise ValueError(f"goal {goal!r}: a walk goes to ENABLED or DISABLED")
        self.label = label
        self.goal = goal
        self.target = _TARGET[goal]
        self.timeout_s = timeout_s
        self.deadline_s = t0_s + timeout_s
        self.attempts = fault_reset_attempts
        self.resets = 0  #: fault resets sent
        self.last_cw: int | None = None  #: the last controlword written (None: none yet)
        self.t_sent_s: float | None = None  #: when it was written [s]
        self.t_nrtso_cw_s: float | None = None  #: when disable voltage went out in Not ready to switch on
        self.seen: tuple[int, float] | None = None  #: the last fresh (statusword, time) used

    def sent(self, t_s: float) -> None:
        """The controlwords of the last step were written (their SDO answered) at ``t_s``."""
        self.t_sent_s = t_s

    def on_statusword(self, sw: int, t_s: float) -> WalkStep:
        """The next step after statusword ``sw`` received at ``t_s`` [s]."""
        if self.t_sent_s is not None and t_s <= self.t_sent_s:
            return self._late(WalkStep(stale=True), t_s)
        self.seen = (sw, t_s)
        state = decode_state(sw)
        if state is self.target:
            return WalkStep(done=True)
        step = self._late(None, t_s)
        if step is not None:
            return step
        cmd = master_command(self.goal, state, stopped=True)
        if cmd is None:  # fault reaction active: the drive's own transition
            return WalkStep()
        if state is State.NOT_READY_TO_SWITCH_ON:
            if self.last_cw == _DV:
                return WalkStep()  # sent: the drive initialises, wait
            self.t_nrtso_cw_s = t_s
            return self._send((_DV,), cmd)
        if cmd is Command.FAULT_RESET:
            if self.resets >= self.attempts:
                return WalkStep(failed=f"{self.label}: still in FAULT after {self.resets} fault resets "
                                       f"(canopen.fault_reset_attempts)", in_fault=True)
            self.resets += 1
            edge = (0,) if self.last_cw is not None and self.last_cw & Controlword.FAULT_RESET else ()
            return self._send((*edge, _RESET), cmd)
        return self._send((controlword(cmd),), cmd)

    def _send(self, words: tuple[int, ...], cmd: Command) -> WalkStep:
        self.last_cw = words[-1]
        return WalkStep(words, cmd.value)

    def _late(self, step: WalkStep | None, t_s: float) -> WalkStep | None:
        """Past the deadline: the step that gives up, naming what was seen and when; else ``step``."""
        if t_s <= self.deadline_s:
            return step
        if self.seen is None:
            seen = ("its statusword never read" if self.t_sent_s is None else
                    f"no statusword read after the command at t = {self.t_sent_s:.3f} s")
        else:
            sw, t = self.seen
            seen = f"statusword 0x{sw:04X} ({decode_state(sw).name}) read at t = {t:.3f} s"
            if self.t_sent_s is not None and t <= self.t_sent_s:
                seen += f", stale since t = {self.t_sent_s:.3f} s (the last command; none read after it)"
        if self.t_nrtso_cw_s is not None and self.seen is not None and \
                decode_state(self.seen[0]) is State.NOT_READY_TO_SWITCH_ON:
            seen += f"; disable voltage (0x0000) sent there at t = {self.t_nrtso_cw_s:.3f} s"
        return WalkStep(failed=f"{self.label}: not in {self.target.name} within canopen.enable_timeout_s = "
                               f"{self.timeout_s} s ({seen})", in_fault=self.seen is not None
                        and decode_state(self.seen[0]) is State.FAULT)


# --------------------------------------------------------------------------- the end of a safe stop


@dataclass(frozen=True, slots=True)
class Confirmed:
    """What the read of one drive's statusword after the safe stop gave: the word and when it was
    received, or why there is none (``problem``)."""

    statusword: int | None = None
    t_s: float | None = None
    problem: str = ""


#: Reads of a drive's statusword after a safe stop before it is given up as not answering
CONFIRM_READS = 3
#: initiate-upload response and abort: the server command specifiers a statusword read is answered with
_SCS_UPLOAD, _SCS_ABORT = 2, 4


class StopConfirmation:
    """Each drive's statusword read by SDO once after the last command of a safe stop (sans-IO).

    Parameters
    ----------
    objects : dict
        Node id -> (index, subindex) of its statusword (the signal map's 0x6041).
    timeout_s : float
        The SDO response timeout (``canopen.sdo_timeout_s``).
    attempts : int
        Reads per drive before it is given up as not answering (:data:`CONFIRM_READS`): a request or
        its answer lost on a noisy bus is asked again; bounded by ``attempts * timeout_s``.

    Its own SDO clients (a transfer of the preflight's left busy does not hold it up); an answer
    that is not the upload of that object (the response to a controlword written by SDO without
    waiting for it, before) is passed over.
    """

    def __init__(self, objects: dict[int, tuple[int, int]], timeout_s: float, attempts: int = CONFIRM_READS) -> None:
        self.objects = dict(objects)
        self.timeout_s = timeout_s
        self.attempts = attempts
        self._clients = {n: SdoClient(n, timeout_s=timeout_s) for n in self.objects}
        self._tries = dict.fromkeys(self.objects, 0)
        self.results: dict[int, Confirmed] = {}

    def start(self, t_s: float) -> list[Frame]:
        """The read requests, one per drive."""
        return [self._ask(n, t_s) for n in self._clients]

    def _ask(self, node: int, t_s: float) -> Frame:
        self._tries[node] += 1
        return self._clients[node].start_upload(*self.objects[node], t_s)

    @property
    def done(self) -> bool:
        return len(self.results) == len(self.objects)

    def on_frame(self, node: int, frame: Frame, t_s: float) -> Confirmed | None:
        """An SDO response of ``node``: the result once its read ended (None: not yet, or not its answer)."""
        c = self._clients.get(node)
        if c is None or node in self.results or len(frame.data) != 8:
            return None
        d = frame.data
        index, sub = self.objects[node]
        if d[0] >> 5 not in (_SCS_UPLOAD, _SCS_ABORT) or d[1:4] != struct.pack("<HB", index, sub):
            return None
        try:
            got = c.on_frame(frame, t_s)
        except SdoAbortError as exc:
            return self._end(node, Confirmed(problem=f"SDO abort 0x{int(exc.code):08X} ({describe(exc.code)})"))
        if isinstance(got, SdoEvent):
            return self._end(node, Confirmed(int.from_bytes(bytes(got.data[:2]).ljust(2, b"\0"), "little"), t_s))
        return None

    def poll(self, t_s: float) -> list[Frame]:
        """Timeouts at ``t_s``: the abort frames to send (the drive's read ends unanswered)."""
        out = []
        for n, c in self._clients.items():
            if n in self.results:
                continue
            try:
                c.poll(t_s)
            except SdoTimeout as exc:
                out.append(exc.abort_frame)
                if self._tries[n] < self.attempts:
                    out.append(self._ask(n, t_s))
                    continue
                self._end(n, Confirmed(problem=f"0x6041 not answered by SDO: {self._tries[n]} reads of "
                                               f"canopen.sdo_timeout_s = {self.timeout_s} s each"))
        return out

    def _end(self, node: int, res: Confirmed) -> Confirmed:
        self.results[node] = res
        return res


def final_state(statusword: int | None, seen_t_s: float | None, confirmed: Confirmed | None, fresh: bool) -> dict:
    """A drive's final state as the record holds it, in words of what was seen.

    Parameters
    ----------
    statusword, seen_t_s
        The last statusword the master received (by PDO or SDO) and when [s]; None: never one.
    confirmed
        The read after the safe stop (None: none was made).
    fresh
        Without that read: the last statusword is fresh (within the heartbeat timeout).

    Returns
    -------
    dict
        ``state`` (the last state seen, None if never read), ``seen_t_s``, ``confirmed`` (observed
        after the last command), ``safe`` (confirmed and in Switch on disabled), ``seen`` (the words).
    """
    state = None if statusword is None else decode_state(statusword)
    if confirmed is not None:
        ok = confirmed.statusword is not None
        if ok:
            words = f"read after the stop at t = {confirmed.t_s:.3f} s"
        elif seen_t_s is None:
            words = f"statusword never read ({confirmed.problem})"
        else:
            words = f"statusword stale since t = {seen_t_s:.3f} s ({confirmed.problem})"
    else:
        ok = fresh and statusword is not None
        words = ("statusword never read" if statusword is None else
                 f"statusword fresh at t = {seen_t_s:.3f} s" if ok else f"statusword stale since t = {seen_t_s:.3f} s")
    return {"state": None if state is None else state.name,
            "seen_t_s": None if seen_t_s is None else round(seen_t_s, 6),
            "confirmed": ok, "safe": ok and state in SAFE_STATES, "seen": words}
