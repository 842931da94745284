"""The one codec of a SYNC cycle's process data: TPDOs -> :class:`Sample`, setpoints -> RPDOs (sans-IO).

Built from the channels of a :class:`~hil.canopen.plan.RigPlan` (where each
signal of each EMA sits in which PDO) with every scale resolved:

* :class:`CycleDecoder` turns the TPDOs of one SYNC cycle, whichever nodes
  send them, into a :class:`~hil.canopen.process.Sample` in SI units plus each
  drive's statusword and modes display. The master uses it live, the CAN-log
  reader on a recording, the simulated nodes' fault injection to change a
  value in a frame: one implementation.
* :class:`SetpointEncoder` turns each drive's controlword, target position
  [rad] and target torque [N] into its RPDOs, and the modes of operation into
  its event RPDO; :meth:`SetpointEncoder.decode` reads them back (the CAN-log
  reader's setpoint columns).

Scaling is :class:`hil.canopen.signalmap.Scale` (``si = raw / k + offset``);
encoded values are rounded to nearest (ties to even) and clipped to their data
type's range (:func:`hil.canopen.pdo.encode_raw`), and every payload goes
through its PDO's codec (:meth:`PdoSpec.pack <hil.canopen.pdo.PdoSpec.pack>`,
:meth:`PdoSpec.unpack <hil.canopen.pdo.PdoSpec.unpack>`). No IO, no clock.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass

from hil.canopen.errors import CanopenInputError
from hil.canopen.frame import Frame
from hil.canopen.pdo import Direction, PdoSpec, encode_raw, raw_encoder
from hil.canopen.plan import Channel
from hil.canopen.process import Sample
from hil.canopen.signalmap import Scale, Signal

__all__ = ["CycleDecoder", "RxValues", "SAMPLE_SLOTS", "SetpointEncoder", "SyncSchedule"]

#: Slot of each physical input in :attr:`CycleDecoder.values` (the order of :class:`Sample` after ``t_s``).
SAMPLE_SLOTS: dict[tuple[int, Signal], int] = {
    (1, Signal.MOTOR_ANGLE): 0, (2, Signal.MOTOR_ANGLE): 1, (1, Signal.LVDT): 2, (2, Signal.LVDT): 3,
    (1, Signal.FORCE): 4, (2, Signal.FORCE): 5}

def _resolved(ch: Channel) -> Scale | None:
    if ch.signal in (Signal.MOTOR_ANGLE, Signal.LVDT, Signal.FORCE, Signal.TARGET_POSITION, Signal.TARGET_TORQUE):
        if ch.scale is None:
            raise CanopenInputError(f"{ch.key}: the scale of {ch.signal.value} is not resolved yet ({ch.source.value})")
        return ch.scale
    return None


class CycleDecoder:
    """TPDOs of one SYNC cycle -> one sample of both EMAs.

    Parameters
    ----------
    pdos : sequence of PdoSpec
        Every TPDO of the rig's layout (all nodes).
    channels : sequence of Channel
        The inputs (motor angle, LVDT, force of both EMAs; statusword and modes
        display of both drives), every physical scale resolved.

    Attributes
    ----------
    values : list of float
        Motor angle 1, 2 [rad], LVDT 1, 2 [mm], force 1, 2 [N] as last decoded.
    statusword, mode_display : list of int or None
        Per EMA (index 0, 1) as last decoded (None before the first).

    Notes
    -----
    A cycle is complete when every TPDO carrying an input has arrived since
    the last :meth:`reset` (the SYNC). A TPDO that carries only objects the
    check does not use (a fixed mapping of an I/O module) is decoded and
    ignored; it is not waited for.
    """

    def __init__(self, pdos: Sequence[PdoSpec], channels: Sequence[Channel]) -> None:
        by_cob = {p.cob_id: p for p in pdos}
        plan: dict[int, list[tuple[int, int, Scale | None]]] = {}
        self.values: list[float] = [0.0] * 6
        self.statusword: list[int | None] = [None, None]
        self.mode_display: list[int | None] = [None, None]
        for ch in channels:
            if ch.signal.direction is not Direction.TX:
                continue
            if ch.cob_id not in by_cob:
                raise CanopenInputError(f"{ch.key}: COB-ID 0x{ch.cob_id:03X} is not a TPDO of the layout")
            if ch.signal is Signal.STATUSWORD:
                slot = 6 + ch.ema - 1
            elif ch.signal is Signal.MODE_DISPLAY:
                slot = 8 + ch.ema - 1
            else:
                slot = SAMPLE_SLOTS[(ch.ema, ch.signal)]
            plan.setdefault(ch.cob_id, []).append((slot, ch.position, _resolved(ch)))
        missing = [k for k, s in SAMPLE_SLOTS.items() if not any(x[0] == s for v in plan.values() for x in v)]
        if missing:
            raise CanopenInputError("no channel for " + ", ".join(f"EMA {e} {sig.value}" for e, sig in missing))
        #: COB-ID -> (PdoSpec, ((slot, position, divisor or None, offset), ...), EMAs whose statusword it carries)
        self._pdos: dict[int, tuple[PdoSpec, tuple, tuple[int, ...]]] = {}
        for cob, items in plan.items():
            rows = tuple((slot, pos, None if sc is None else sc.units_per_si, 0.0 if sc is None else sc.offset)
                         for slot, pos, sc in sorted(items))
            status_emas = tuple(slot - 5 for slot, _, _, _ in rows if slot in (6, 7))
            self._pdos[cob] = (by_cob[cob], rows, status_emas)
        #: :meth:`feed`'s: COB-ID -> (the PdoSpec's codec unpack, PdoSpec, rows, status EMAs)
        self._feed = {cob: (spec.codec.unpack, spec, rows, emas) for cob, (spec, rows, emas) in self._pdos.items()}
        self._others = frozenset(c for c in by_cob if c not in self._pdos)
        self._expected = frozenset(self._pdos)
        self._n_expected = len(self._expected)
        self._got: set[int] = set()

    @property
    def cob_ids(self) -> frozenset[int]:
        """COB-IDs of the TPDOs a complete cycle needs."""
        return self._expected

    def reset(self) -> None:
        """A SYNC: a new cycle starts (nothing of it has arrived)."""
        self._got.clear()

    def feed(self, frame: Frame) -> tuple[int, ...] | None:
        """Decode one frame; returns None if it is no TPDO of the layout, else the EMAs (1, 2)
        whose statusword it carried. Raises :class:`~hil.canopen.pdo.PdoLengthError` on a wrong length."""
        cob = frame.arbitration_id
        hit = self._feed.get(cob)
        if hit is None:
            if cob in self._others:
                return ()
            return None
        unpack, spec, rows, status_emas = hit
        try:
            vals = unpack(frame.data)  # the PDO's codec (PdoSpec.unpack but for the message of its error)
        except struct.error:
            vals = spec.unpack(frame)  # raises PdoLengthError naming the PDO, its COB-ID and both lengths
        for slot, pos, k, off in rows:
            v = vals[pos]
            if slot < 6:
                v = v / k
                self.values[slot] = v + off if off else v
            elif slot < 8:
                self.statusword[slot - 6] = v
            else:
                self.mode_display[slot - 8] = v
        self._got.add(cob)
        return status_emas

    @property
    def complete(self) -> bool:
        """Every TPDO with an input has arrived since the last :meth:`reset`."""
        return len(self._got) == self._n_expected

    def missing(self) -> list[int]:
        """COB-IDs of this cycle's TPDOs that have not arrived."""
        return sorted(self._expected - self._got)

    def sample(self, t_s: float) -> Sample:
        """The cycle's sample at time ``t_s`` [s] (the values as last decoded)."""
        v = self.values
        return Sample(t_s, v[0], v[1], v[2], v[3], v[4], v[5])

    def scaled(self, frame: Frame) -> dict[tuple[int, Signal], float]:
        """The physical inputs one TPDO carries, ``(ema, signal) -> SI``, without touching the cycle."""
        hit = self._pdos.get(frame.arbitration_id)
        if hit is None:
            return {}
        spec, rows, _ = hit
        vals = spec.unpack(frame)
        out = {}
        for slot, pos, k, off in rows:
            if k is not None:
                key = next(key for key, s in SAMPLE_SLOTS.items() if s == slot)
                out[key] = vals[pos] / k + off
        return out

    def rescaled(self, frame: Frame, changes: dict[tuple[int, Signal], float]) -> Frame:
        """``frame`` with the physical inputs in ``changes`` (``(ema, signal) -> SI``) re-encoded."""
        hit = self._pdos.get(frame.arbitration_id)
        if hit is None or not changes:
            return frame
        spec, rows, _ = hit
        vals = list(spec.unpack(frame))
        for slot, pos, k, off in rows:
            key = next((key for key, s in SAMPLE_SLOTS.items() if s == slot), None)
            if key in changes and k is not None:
                vals[pos] = encode_raw(spec.entries[pos].data_type, (changes[key] - off) * k)
        return spec.pack(vals)


@dataclass(frozen=True, slots=True)
class RxValues:
    """What one RPDO carried for one EMA (raw and SI; None where the PDO does not carry it)."""

    ema: int
    controlword: int | None = None
    target_position_rad: float | None = None
    target_torque_N: float | None = None
    mode: int | None = None


class SetpointEncoder:
    """Setpoints of both drives -> their RPDO frames (and back).

    Parameters
    ----------
    pdos : sequence of PdoSpec
        Every RPDO of the rig's layout.
    channels : sequence of Channel
        The outputs (controlword, target position, target torque, modes of
        operation) of both drives, every physical scale resolved.
    """

    def __init__(self, pdos: Sequence[PdoSpec], channels: Sequence[Channel]) -> None:
        by_cob = {p.cob_id: p for p in pdos}
        sync: dict[int, dict[int, list[tuple[int, Signal, Scale | None]]]] = {1: {}, 2: {}}
        self._mode: dict[int, PdoSpec] = {}
        decode: dict[int, list] = {}
        for ch in channels:
            if ch.signal.direction is not Direction.RX:
                continue
            spec = by_cob.get(ch.cob_id)
            if spec is None:
                raise CanopenInputError(f"{ch.key}: COB-ID 0x{ch.cob_id:03X} is not an RPDO of the layout")
            if ch.signal is Signal.MODE:
                if len(spec.entries) != 1:
                    raise CanopenInputError(f"{ch.key}: the modes of operation needs an RPDO of its own")
                self._mode[ch.ema] = spec
            else:
                sync[ch.ema].setdefault(ch.cob_id, []).append((ch.position, ch.signal, _resolved(ch)))
            decode.setdefault(ch.cob_id, [ch.ema]).append((ch.position, ch.signal, _resolved(ch)))
        #: COB-ID -> (PdoSpec, EMA, ((position, signal, scale), ...)) for :meth:`decode`
        self._decode = {cob: (by_cob[cob], rows[0], tuple(rows[1:])) for cob, rows in decode.items()}
        #: per EMA: ((PdoSpec, ((position, signal, units per SI, data type), ...)), ...)
        self._sync: dict[int, tuple] = {}
        for ema in (1, 2):
            out = []
            for cob, items in sync[ema].items():
                spec = by_cob[cob]
                if len(items) != len(spec.entries):
                    raise CanopenInputError(f"{spec.name} COB-ID 0x{cob:03X} carries objects the check does not set")
                rows = tuple((pos, sig, None if sc is None else sc.units_per_si, spec.entries[pos].data_type)
                             for pos, sig, sc in sorted(items, key=lambda x: x[0]))
                out.append((spec, rows))
            self._sync[ema] = tuple(out)
        #: :meth:`frames`' plan per EMA: ((PdoSpec, ((kind, units per SI, raw encoder of the data type),
        #: ...)), ...), kind 0 the controlword, 1 the target position, 2 the target torque
        self._fast: dict[int, tuple] = {
            ema: tuple((spec, tuple((0 if sig is Signal.CONTROLWORD else 1 if sig is Signal.TARGET_POSITION else 2,
                                     k, raw_encoder(t)) for _, sig, k, t in rows))
                       for spec, rows in per_ema)
            for ema, per_ema in self._sync.items()}

    def has_mode_pdo(self, ema: int) -> bool:
        """True when the EMA's modes of operation travels in an RPDO (CST in use)."""
        return ema in self._mode

    def frames(self, ema: int, controlword: int, target_position_rad: float, target_torque_N: float) -> list[Frame]:
        """The synchronous RPDOs of one drive for the next SYNC.

        The target position is ``round(phi * k)`` clipped to its type, the
        target torque ``round(F * k)`` (per mille of the rated torque) clipped
        to its type.
        """
        out = []
        for spec, rows in self._fast[ema]:  # (loops, not comprehensions: each of those is a call, every cycle)
            vals = []
            for kind, k, encode in rows:
                vals.append(controlword if kind == 0 else
                            encode((target_position_rad if kind == 1 else target_torque_N) * k))
            out.append(spec.pack(vals))
        return out

    def mode_frame(self, ema: int, mode: int) -> Frame | None:
        """The event RPDO that sets the modes of operation, None when the EMA has none."""
        spec = self._mode.get(ema)
        return None if spec is None else spec.pack((mode,))

    def decode(self, frame: Frame) -> RxValues | None:
        """What an RPDO of the layout carries (the CAN-log reader's setpoints); None for other frames."""
        hit = self._decode.get(frame.arbitration_id)
        if hit is None:
            return None
        spec, ema, rows = hit
        vals = spec.unpack(frame)
        kw = {}
        for pos, sig, sc in rows:
            v = vals[pos]
            if sig is Signal.CONTROLWORD:
                kw["controlword"] = v
            elif sig is Signal.MODE:
                kw["mode"] = v
            elif sig is Signal.TARGET_POSITION:
                kw["target_position_rad"] = sc.to_si(v)
            else:
                kw["target_torque_N"] = sc.to_si(v)
        return RxValues(ema, **kw)


# --------------------------------------------------------------------------- the process image as data


def image_of(pdos: Sequence[PdoSpec], channels: Sequence[Channel]) -> dict:
    """The layout and the scaled channels as plain data (meta.json's ``process_image``): enough to decode a
    CAN log of the run without the profile, the EDS files or the drives (:func:`from_image`)."""
    return {
        "pdos": [{"name": p.name, "direction": p.direction.value, "cob_id": p.cob_id,
                  "transmission_type": p.transmission_type,
                  "entries": [[e.name, e.index, e.subindex, e.data_type] for e in p.entries]} for p in pdos],
        "channels": [{"signal": c.signal.value, "ema": c.ema, "node": c.node_id, "cob_id": c.cob_id,
                      "position": c.position, "data_type": c.data_type, "source": c.source.value, "key": c.key,
                      "units_per_si": None if c.scale is None else c.scale.units_per_si,
                      "offset": None if c.scale is None else c.scale.offset} for c in channels],
    }


def from_image(image: dict) -> tuple[tuple[PdoSpec, ...], tuple[Channel, ...]]:
    """The inverse of :func:`image_of`; CanopenInputError naming what is malformed."""
    from hil.canopen.pdo import MappedObject
    from hil.canopen.signalmap import ScaleSource

    try:
        pdos = tuple(PdoSpec(p["name"], Direction(p["direction"]), int(p["name"][4:]), int(p["cob_id"]),
                             int(p["transmission_type"]),
                             tuple(MappedObject(str(n), int(i), int(s), int(t)) for n, i, s, t in p["entries"]))
                     for p in image["pdos"])
        chans = tuple(Channel(Signal(c["signal"]), int(c["ema"]), int(c["node"]), int(c["cob_id"]),
                              int(c["position"]), int(c["data_type"]),
                              None if c["units_per_si"] is None else Scale(c["units_per_si"], c["offset"]),
                              ScaleSource(c["source"]), str(c["key"])) for c in image["channels"])
    except (KeyError, TypeError, ValueError) as exc:
        raise CanopenInputError(f"process image: malformed ({type(exc).__name__}: {exc})") from None
    return pdos, chans


class SyncSchedule:
    """The SYNC period each SYNC of the cyclic phase answers: the time of its sample.

    A SYNC comes within T/2 of one period after the last one unless periods
    passed without a SYNC (the kernel's or a drive's timer; the master's own
    loop-timed SYNC is given its slot's time), so the periods between two
    SYNCs are the nearest whole number of periods, at least one,

    .. math:: k_n = k_{n-1} + \\max(1,\\ \\lfloor (t_n - t_{n-1})/T + 1/2 \\rfloor), \\qquad k_1 = 1,

    and the sample answering it is at :math:`k_n T` [s], however many SYNCs
    were seen: periods without a SYNC (its producer was late) are counted in
    :attr:`skipped`, not read as one period's motion. Counted from the last
    SYNC, not the first: a producer whose clock runs apart from this one (a
    drive as SYNC producer, 100 ppm is 0.2 us per 2 ms period) never makes a
    period appear skipped.
    """

    def __init__(self, period_s: float) -> None:
        self.T = period_s
        self.slot = 0  #: the period of the last SYNC (1: the first), 0 before it
        self.skipped = 0  #: periods passed without a SYNC
        self._t_last = 0.0  #: when the last SYNC came [s]

    def on_sync(self, t: float) -> int:
        """A SYNC at ``t`` [s]; returns the periods skipped before it (0 on time)."""
        if self.slot == 0:
            self._t_last, self.slot = t, 1
            return 0
        skipped = int((t - self._t_last) / self.T - 0.5)
        self._t_last = t
        if skipped <= 0:  # (on time: every SYNC)
            self.slot += 1
            return 0
        self.slot += 1 + skipped
        self.skipped += skipped
        return skipped

    @property
    def t_s(self) -> float:
        """The time of the last SYNC's period [s] (``slot`` T)."""
        return self.slot * self.T

    def on_axis(self, t: float) -> float:
        """A time ``t`` on the receiver's clock (a frame's arrival, the master's poll) [s] on the samples' axis
        (:attr:`t_s`, the time of ``signals.csv`` and of the master's stalls) [s]: ``t`` less the last SYNC's
        arrival, plus its period's time (before the first SYNC: ``t`` itself; the axes then differ by the
        preflight, seconds)."""
        return t if self.slot == 0 else t - self._t_last + self.slot * self.T

