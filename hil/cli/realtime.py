"""Real-time set-up of a cyclic process (``emacheck run`` and ``emacheck sim-serve``), best effort.

Locked memory (no page fault inside a SYNC cycle), the garbage collector
frozen or off, the CPUs kept awake (a wake-up latency request), SCHED_FIFO on
request; each function says what it managed.
"""

from __future__ import annotations

import gc
import os


def lock_memory() -> str:
    """Lock the process's pages in RAM (``mlockall(MCL_CURRENT | MCL_FUTURE)``), best effort.

    A page fault in the middle of a SYNC cycle costs time the drives do not
    have (in user-mode-linux about 0.1 ms each); locked pages are faulted in
    once, here. Returns "locked" or why not.
    """
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        if libc.mlockall(1 | 2) != 0:
            return f"not locked ({os.strerror(ctypes.get_errno())})"
    except (OSError, AttributeError) as exc:
        return f"not locked ({exc})"
    return "locked"


def realtime_priority(priority: int = 50) -> str:
    """Run this process under SCHED_FIFO ``priority``, best effort.

    Real drives answer a SYNC within microseconds whatever the master does;
    the simulated ones must not wait for the master's time slice on a shared
    CPU. Returns "SCHED_FIFO N" or why not.
    """
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        return f"normal scheduling ({exc})"
    return f"SCHED_FIFO {priority}"


#: where Linux takes a process's CPU wake-up latency request (PM QoS): held while the file is open
CPU_LATENCY_DEVICE = "/dev/cpu_dma_latency"
_latency_fd: int | None = None  #: the open request (one per process), released by end_realtime()


def hold_cpu_latency(max_us: int, device: str = CPU_LATENCY_DEVICE) -> str:
    """Ask Linux to keep every CPU able to wake within ``max_us`` microseconds (PM QoS
    ``cpu_dma_latency``, as cyclictest does), held until :func:`end_realtime` or the process ends.

    An idle CPU that halts can take long to wake where the wake-up costs much (a deep C-state, a
    virtual machine's vCPU). With 0, idle CPUs poll instead of sleeping (they draw power, and in a
    VM the host's CPU, while the loop runs). Measured in this project's 2-core VM (haltpoll
    cpuidle), a lone SCHED_FIFO process sleeping to 2 ms deadlines for 40 s: woken up to 7.7 ms
    late (6 times over 3 ms) without the request, at most 0.34 ms with 0 us; but with both
    processes of a two-process check running and polling, both loops stood still about 6 ms at
    0.1 s boundaries, every 0.1-0.4 s (the pattern of a host capping the VM's CPU time per 100 ms),
    so the commands ask for it only when told (``--cpu-latency-us``). Returns what was done.
    """
    global _latency_fd
    if max_us < 0:
        raise ValueError(f"max_us = {max_us}: a wake-up latency is >= 0 us")
    try:
        fd = os.open(device, os.O_WRONLY)
    except OSError as exc:
        return f"CPU wake-up latency not held ({device}: {exc.strerror})"
    try:
        os.write(fd, max_us.to_bytes(4, "little", signed=True))
    except OSError as exc:
        os.close(fd)
        return f"CPU wake-up latency not held ({device}: {exc.strerror})"
    release_cpu_latency()
    _latency_fd = fd
    return f"CPU wake-up latency <= {max_us} us requested"


def release_cpu_latency() -> None:
    """Let go of the request :func:`hold_cpu_latency` made (nothing if none)."""
    global _latency_fd
    if _latency_fd is not None:
        fd, _latency_fd = _latency_fd, None
        os.close(fd)


def end_realtime() -> None:
    """After a bounded cyclic loop (:func:`prepare_realtime` with ``bounded=True``): the garbage
    collector back on, the CPU wake-up latency request let go, SCHED_OTHER (analysis and plotting
    must not run real-time)."""
    gc.enable()
    release_cpu_latency()
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        pass


def prepare_realtime(priority: int, *, bounded: bool = False, cpu_latency_us: int | None = None) -> str:
    """Set this process up for a cyclic loop: memory locked, GC frozen, the CPUs' wake-up latency
    held at ``cpu_latency_us`` (:func:`hold_cpu_latency`; None: not asked), SCHED_FIFO ``priority`` if > 0.

    ``gc.freeze`` moves every object made so far (profiles, object dictionaries,
    imported modules) out of the collector's reach, so no collection inside a
    SYNC cycle scans them. ``bounded`` (a loop that ends, like the check of
    ``emacheck run``): the cyclic collector is switched off until
    :func:`end_realtime` (reference counting still frees the loop's objects;
    no collection pause can fall into a SYNC cycle). Returns what was done,
    for the terminal.
    """
    memory = lock_memory()
    sched = realtime_priority(priority) if priority > 0 else "normal scheduling"
    wake = "" if cpu_latency_us is None else f", {hold_cpu_latency(cpu_latency_us)}"
    gc.collect()
    gc.freeze()
    if bounded:
        gc.disable()
    return f"memory {memory}, {sched}{wake}" + (", garbage collector off" if bounded else "")
