"""Real-time set-up of a cyclic process (``emacheck run`` and ``emacheck sim-serve``), best effort.

Locked memory (no page fault inside a SYNC cycle) and a held heap (a buffer
allocated in the cycle reuses faulted pages), the garbage collector frozen or
off, the CPUs kept awake (a wake-up latency request), SCHED_FIFO on request;
each function says what it managed.
"""

from __future__ import annotations

import functools
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


#: glibc's ``mallopt`` parameters (<malloc.h>) and the defaults :func:`release_heap` puts back
M_TRIM_THRESHOLD, M_MMAP_MAX = -1, -4
DEFAULT_TRIM_THRESHOLD_BYTES, DEFAULT_MMAP_MAX = 128 * 1024, 65536
#: the heap :func:`hold_heap` grows and keeps for a cyclic loop [bytes]
HEAP_RESERVE_BYTES = 32 << 20
_heap_held = False


@functools.cache
def _glibc():
    """glibc's ``mallopt``, ``malloc``, ``free`` and ``malloc_trim`` with their C signatures (loaded once);
    AttributeError where the C library is not glibc's."""
    import ctypes
    import ctypes.util

    libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
    for name in ("mallopt", "malloc", "free", "malloc_trim"):
        getattr(libc, name)  # AttributeError where the C library is not glibc's
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    libc.malloc_trim.argtypes = [ctypes.c_size_t]
    return libc


def hold_heap(reserve_bytes: int = HEAP_RESERVE_BYTES) -> str:
    """Keep the C heap's freed memory in the process and grow the heap by ``reserve_bytes`` now, best
    effort (glibc only).

    Locked memory alone does not keep a cycle free of page faults: glibc gives a block of 128 KiB
    or more its own ``mmap`` and unmaps it when freed, and returns the heap's free top to the
    system (``brk``) once it exceeds the trim threshold; the next such buffer (a list grown past
    16 384 items, a numpy temporary) is mapped and faulted in again, page by page (4 KiB each;
    measured inside user-mode-linux: 264 faults, 1 MiB, in one check's cyclic loop, ~0.9 ms each).
    As the real-time Linux guidance has it (``mallopt(M_TRIM_THRESHOLD, -1)``,
    ``mallopt(M_MMAP_MAX, 0)``, then a reserve allocated, touched and freed), large blocks then come
    from the heap, freed memory stays there, and the reserve's pages are faulted in here, before
    the loop. Python's own small-object arenas (1 MiB each, mapped by the interpreter) are not
    affected. Undone by :func:`release_heap` (called by :func:`end_realtime`). Returns what was done.
    """
    global _heap_held
    import ctypes

    if reserve_bytes < 0:
        raise ValueError(f"reserve_bytes = {reserve_bytes}: a heap reserve is >= 0 bytes")
    try:
        libc = _glibc()
    except (OSError, AttributeError) as exc:
        return f"heap not held ({exc})"
    if not (libc.mallopt(M_TRIM_THRESHOLD, -1) and libc.mallopt(M_MMAP_MAX, 0)):
        return "heap not held (mallopt refused)"
    _heap_held = True
    if reserve_bytes:
        ptr = libc.malloc(reserve_bytes)
        if not ptr:
            return f"heap held, no reserve ({reserve_bytes >> 20} MiB not available)"
        ctypes.memset(ptr, 0, reserve_bytes)  # every page faulted in (and locked, under mlockall) now
        libc.free(ptr)  # stays in the heap: nothing is trimmed
    return f"heap held ({reserve_bytes / (1 << 20):g} MiB reserve)"


def release_heap() -> None:
    """Undo :func:`hold_heap`: glibc's defaults back (fixed at their default values) and the heap's
    free memory returned to the system (nothing if the heap was not held)."""
    global _heap_held
    if not _heap_held:
        return
    _heap_held = False
    try:
        libc = _glibc()
    except (OSError, AttributeError):
        return
    libc.mallopt(M_MMAP_MAX, DEFAULT_MMAP_MAX)
    libc.mallopt(M_TRIM_THRESHOLD, DEFAULT_TRIM_THRESHOLD_BYTES)
    libc.malloc_trim(0)


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
    collector back on, the CPU wake-up latency request let go, the heap let go (:func:`release_heap`),
    SCHED_OTHER (analysis and plotting must not run real-time)."""
    gc.enable()
    release_heap()
    release_cpu_latency()
    try:
        if os.sched_getscheduler(0) != os.SCHED_OTHER:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        pass


def prepare_realtime(priority: int, *, bounded: bool = False, cpu_latency_us: int | None = None) -> str:
    """Set this process up for a cyclic loop: memory locked, the heap held (:func:`hold_heap`), GC frozen, the
    CPUs' wake-up latency held at ``cpu_latency_us`` (:func:`hold_cpu_latency`; None: not asked), SCHED_FIFO
    ``priority`` if > 0.

    ``gc.freeze`` moves every object made so far (profiles, object dictionaries,
    imported modules) out of the collector's reach, so no collection inside a
    SYNC cycle scans them. ``bounded`` (a loop that ends, like the check of
    ``emacheck run``): the cyclic collector is switched off until
    :func:`end_realtime` (reference counting still frees the loop's objects;
    no collection pause can fall into a SYNC cycle). Returns what was done,
    for the terminal.
    """
    memory = lock_memory()
    heap = hold_heap()
    sched = realtime_priority(priority) if priority > 0 else "normal scheduling"
    wake = "" if cpu_latency_us is None else f", {hold_cpu_latency(cpu_latency_us)}"
    gc.collect()
    gc.freeze()
    if bounded:
        gc.disable()
    return f"memory {memory}, {heap}, {sched}{wake}" + (", garbage collector off" if bounded else "")
