"""The CAN log's batch formatter (issue 38): byte for byte the lines of python-can's candump writer.

:func:`hil.record.canlog.candump_lines` formats a batch of frames at each flush; python-can's
:class:`can.io.CanutilsLogWriter` is the reference it must match on any frame a bus can deliver
(standard and extended identifiers, remote and error frames, CAN FD flags, 0-8 bytes, any time,
times before the first frame's, any channel), across batch boundaries too.
"""

from __future__ import annotations

import io

import can
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hil.canopen.frame import Frame
from hil.record.canlog import CanLogWriter, FrameKind, candump_lines

times = st.one_of(st.floats(min_value=0.0, max_value=2e9, allow_nan=False),
                  st.floats(min_value=0.0, max_value=200.0, allow_nan=False),
                  st.integers(0, 10**6).map(lambda k: k * 0.002))


@st.composite
def messages(draw) -> can.Message:
    ext = draw(st.booleans())
    fd = draw(st.booleans()) and draw(st.booleans())
    return can.Message(
        timestamp=draw(times),
        arbitration_id=draw(st.integers(0, 0x1FFFFFFF if ext else 0x7FF)),
        is_extended_id=ext,
        is_remote_frame=draw(st.booleans()) and not fd and draw(st.booleans()),
        is_error_frame=draw(st.booleans()) and draw(st.booleans()) and draw(st.booleans()),
        is_fd=fd,
        bitrate_switch=fd and draw(st.booleans()),
        error_state_indicator=fd and draw(st.booleans()),
        is_rx=draw(st.booleans()),
        channel=draw(st.one_of(st.none(), st.none(), st.sampled_from(["vcan0", "can1", "3", 2]))),
        data=draw(st.binary(min_size=0, max_size=8)),
        check=False,
    )


def _python_can(msgs: list[can.Message], channel) -> str:
    buf = io.StringIO()
    w = can.io.CanutilsLogWriter(buf, channel=channel)
    for m in msgs:
        w.on_message_received(m)
    return buf.getvalue()


def _record(m: can.Message):
    return (m.timestamp, m.arbitration_id, bytes(m.data), m.is_rx, FrameKind.of(m))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(messages(), min_size=0, max_size=40), st.sampled_from(["can0", "vcan-dry-run", "0", 1]),
       st.integers(1, 41))
def test_batch_lines_are_python_cans_lines(msgs, channel, batch):
    want = _python_can(msgs, channel)
    records = [_record(m) for m in msgs]
    got, first = [], None
    for k in range(0, len(records), batch):  # in batches, the first frame's time carried across
        text, first = candump_lines(records[k:k + batch], channel, first)
        got.append(text)
    assert "".join(got) == want


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.integers(0, 0x7FF), st.binary(max_size=8), times, st.booleans()), max_size=60),
       st.floats(min_value=0.0, max_value=2e9, allow_nan=False))
def test_writer_file_is_python_cans_file(tmp_path_factory, frames, offset):
    """The log writer (frames of the stack, an offset added to each time, formatted every 5 frames,
    flushed every 7) writes the file python-can's writer writes from the equivalent messages."""
    path = tmp_path_factory.mktemp("log") / "can.log"
    w = CanLogWriter(path, channel="can0", flush_frames=7, time_offset_s=offset, format_frames=5)
    msgs = []
    for cid, data, t, rx in frames:
        w.write(Frame(cid, data), t, rx)
        msgs.append(can.Message(timestamp=t + offset if offset else t, arbitration_id=cid, data=data,
                                is_extended_id=False, is_rx=rx, check=False))
    w.close()
    assert path.read_text() == _python_can(msgs, "can0")
    assert w.frames == len(frames)


def test_a_dry_run_like_batch():
    """Many frames of the shapes a dry-run logs (SYNC, PDOs, heartbeats) at 2 ms steps."""
    import random

    rnd = random.Random(38)
    msgs = []
    for k in range(5000):
        t = 0.002 * k
        for cid, n, rx in ((0x080, 0, False), (0x181, 8, True), (0x182, 8, True), (0x281, 6, True),
                           (0x201, 8, False), (0x701, 1, True), (0x77F, 1, False)):
            msgs.append(can.Message(timestamp=t, arbitration_id=cid, data=rnd.randbytes(n), is_extended_id=False,
                                    is_rx=rx, check=False))
    text, _ = candump_lines([_record(m) for m in msgs], "vcan-dry-run")
    assert text == _python_can(msgs, "vcan-dry-run")


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(messages(), st.booleans(), st.integers(1, 4)), max_size=40))
def test_received_runs_with_and_without_messages(tmp_path_factory, items):
    """Frames received in runs (:meth:`CanLogWriter.write_received`): without a python-can message (in
    process, the SocketCAN fast path: received, the log's channel) or with the bus's message (its
    channel, direction and kind kept), mixed with frames sent: python-can's file from the same messages."""
    path = tmp_path_factory.mktemp("log") / "can.log"
    w = CanLogWriter(path, channel="vcan0", flush_frames=9, format_frames=4)
    want, run = [], []
    for msg, bare, n in items:
        for _ in range(n):
            if bare:
                f = Frame(msg.arbitration_id & 0x7FF, bytes(msg.data))
                run.append((f, msg.timestamp, None))
                want.append(can.Message(timestamp=msg.timestamp, arbitration_id=f.arbitration_id, data=f.data,
                                        is_extended_id=False, is_rx=True, check=False))
            else:
                run.append((Frame(0, b""), msg.timestamp, msg))
                want.append(msg)
        if len(run) > 3 or bare:
            w.write_received(run)
            run = []
            sent = Frame(0x201, b"\x0f\x00")
            w.write(sent, msg.timestamp, False)
            want.append(can.Message(timestamp=msg.timestamp, arbitration_id=0x201, data=sent.data,
                                    is_extended_id=False, is_rx=False, check=False))
    w.write_received(run)
    w.close()
    assert path.read_text() == _python_can(want, "vcan0")
