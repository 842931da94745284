"""The vcan stage: a SocketCAN ``vcan0``, on the host kernel or inside user-mode-linux.

Where the host kernel has CAN (AF_CAN sockets and the vcan driver), ``vcan0``
is used (or created) there. Elsewhere Debian's ``user-mode-linux`` kernel is
booted as an ordinary process with the host's file system as its root
(hostfs), so the same Python, site-packages and project tree are inside; its
init script mounts /proc, /sys and /dev/shm, loads can, can-raw, can-bcm,
can-dev and vcan from ``/usr/lib/uml/modules/VERSION/``, creates ``vcan0``,
runs one command (the inner SocketCAN tests, or the benchmark) with the
host's environment plus ``EMACHECK_INSIDE_UML=1``, writes its exit status to a
file the host reads back, and halts.

UML 6.1 on hosts with a large XSAVE area (AVX-512, AMX) needs the
LD_PRELOAD shim ``xstate_shim.c`` (built here with the host's C compiler): see
the comment at its top.

Used by ``tests/test_vcan.py`` (the stage in the default test run) and
``tests/bench/bench_vcan.py``. Nothing here is collected by pytest.
"""

from __future__ import annotations

import contextlib
import os
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

INSIDE_ENV = "EMACHECK_INSIDE_UML"
CHANNEL = "vcan0"
HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
UML_KERNEL = "linux.uml"
UML_MODULES = Path("/usr/lib/uml/modules")
#: Module load order (dependencies first), relative to the modules' ``kernel/``.
CAN_MODULES = ("net/can/can.ko", "net/can/can-raw.ko", "net/can/can-bcm.ko",
               "drivers/net/can/dev/can-dev.ko", "drivers/net/can/vcan.ko")
APT_HINT = "apt-get install user-mode-linux kmod can-utils gcc"
#: Exit status the init script writes when the setup inside UML failed.
SETUP_FAILED = 97


def inside_uml() -> bool:
    return os.environ.get(INSIDE_ENV) == "1"


def _run(cmd: list[str], timeout: float = 10.0) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


def af_can_problem() -> str | None:
    """None if this kernel opens CAN_RAW sockets, else why not."""
    if not hasattr(socket, "AF_CAN"):
        return "this Python has no socket.AF_CAN"
    try:
        s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    except OSError as exc:
        return f"AF_CAN sockets unsupported by this kernel ({exc.strerror})"
    s.close()
    return None


def host_vcan(channel: str = CHANNEL) -> tuple[bool, str]:
    """Make ``channel`` a usable vcan on this kernel: (True, how) or (False, why not)."""
    why = af_can_problem()
    if why:
        return False, why
    ip = shutil.which("ip") or "/usr/sbin/ip"
    if not Path(f"/sys/class/net/{channel}").exists():
        try:
            r = _run([ip, "link", "add", "dev", channel, "type", "vcan"])
        except (OSError, subprocess.TimeoutExpired) as exc:
            return False, f"`ip link add dev {channel} type vcan` failed: {exc}"
        if r.returncode != 0:
            return False, f"`ip link add dev {channel} type vcan`: {r.stderr.strip() or r.returncode}"
        how = f"{channel} created on the host kernel"
    else:
        how = f"{channel} exists on the host kernel"
    flags = Path(f"/sys/class/net/{channel}/flags")
    if flags.exists() and not int(flags.read_text(), 16) & 1:
        r = _run([ip, "link", "set", "up", channel])
        if r.returncode != 0:
            return False, f"`ip link set up {channel}`: {r.stderr.strip() or r.returncode}"
    return True, how


def _which(name: str) -> str | None:
    return shutil.which(name) or next((str(p) for d in ("/usr/sbin", "/sbin", "/usr/bin", "/bin")
                                       if (p := Path(d) / name).exists()), None)


def uml_modules_dir() -> Path | None:
    """``/usr/lib/uml/modules/VERSION`` holding all CAN modules (newest version), or None."""
    if not UML_MODULES.is_dir():
        return None
    for d in sorted(UML_MODULES.iterdir(), reverse=True):
        if all((d / "kernel" / m).exists() for m in CAN_MODULES):
            return d
    return None


def uml_problem() -> str | None:
    """None if user-mode-linux can run the stage here, else what is missing."""
    if _which(UML_KERNEL) is None:
        return f"user-mode-linux not installed ({APT_HINT})"
    if uml_modules_dir() is None:
        return f"no UML kernel modules with CAN under {UML_MODULES} ({APT_HINT})"
    for tool, pkg in (("insmod", "kmod"), ("ip", "iproute2"), ("candump", "can-utils"), ("halt", "systemd-sysv")):
        if _which(tool) is None:
            return f"`{tool}` not found (package {pkg}; {APT_HINT})"
    if shutil.which("gcc") is None and shutil.which("cc") is None:
        return f"no C compiler for the UML xstate shim ({APT_HINT})"
    if not Path("/dev/shm").is_dir():
        return "no /dev/shm for the UML memory file"
    return None


def build_shim(workdir: Path) -> Path:
    """Compile ``xstate_shim.c`` into ``workdir``; raises RuntimeError with the compiler output."""
    out = workdir / "xstate_shim.so"
    cc = shutil.which("gcc") or shutil.which("cc")
    r = _run([cc, "-O2", "-shared", "-fPIC", "-o", str(out), str(HERE / "xstate_shim.c"), "-ldl"], timeout=60)
    if r.returncode != 0:
        raise RuntimeError(f"building the UML xstate shim failed: {r.stderr.strip()}")
    return out


def precompile(root: Path = ROOT) -> None:
    """Write the project's bytecode (``__pycache__``) on the host, before booting UML.

    Inside UML every page fault costs about 0.9 ms and every system call about
    0.12 ms; compiling the project's sources at each interpreter start (as
    happens where PYTHONDONTWRITEBYTECODE is set, or the tree is read-only)
    costs each process there tens of seconds. Installed packages were compiled
    by pip.
    """
    dirs = [str(root / d) for d in ("hil", "blf", "sim", "profiles", "tests") if (root / d).is_dir()]
    r = subprocess.run([sys.executable, "-m", "compileall", "-q", *dirs], capture_output=True, text=True,
                       timeout=300)
    if r.returncode != 0:
        raise RuntimeError(f"compileall failed: {r.stdout[-2000:]}{r.stderr[-2000:]}")


def _init_script(workdir: Path, command: list[str], env: dict[str, str], cwd: Path) -> Path:
    mod = uml_modules_dir()
    assert mod is not None
    ins, ip, halt = _which("insmod"), _which("ip"), _which("halt")
    status = workdir / "status"
    lines = [
        "#!/bin/sh",
        "# generated by tests/vcan/vcan_stage.py: runs as init (PID 1) inside user-mode-linux",
        "PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin; export PATH",
        f"fail() {{ echo \"vcan stage setup: $1\" >> {shlex.quote(str(workdir / 'inner.log'))}; "
        f"echo {SETUP_FAILED} > {shlex.quote(str(status))}; {halt} -f; exit 1; }}",
        "mount -t proc proc /proc || fail 'mount /proc'",
        "mount -t sysfs sysfs /sys || fail 'mount /sys'",
        "mkdir -p /dev/shm && mount -t tmpfs tmpfs /dev/shm || fail 'mount /dev/shm'",
        "ip link set up lo",
    ]
    for m in CAN_MODULES:
        p = shlex.quote(str(mod / "kernel" / m))
        lines.append(f"{ins} {p} || fail 'insmod {m}'")
    lines += [
        f"{ip} link add dev {CHANNEL} type vcan || fail 'ip link add {CHANNEL}'",
        f"{ip} link set up {CHANNEL} || fail 'ip link set up {CHANNEL}'",
        f"date +%s.%N > {shlex.quote(str(workdir / 'booted'))}",
    ]
    for k, v in sorted(env.items()):
        lines.append(f"{k}={shlex.quote(v)}; export {k}")
    cmd = " ".join(shlex.quote(c) for c in command)
    lines += [
        f"cd {shlex.quote(str(cwd))} || fail 'cd {cwd}'",
        f"{cmd} > {shlex.quote(str(workdir / 'inner.log'))} 2>&1",
        f"echo $? > {shlex.quote(str(status))}",
        f"{halt} -f",
    ]
    p = workdir / "init.sh"
    p.write_text("\n".join(lines) + "\n")
    p.chmod(0o755)
    return p


_ENV_DROP = ("LD_PRELOAD", "PYTEST_CURRENT_TEST", "PYTEST_XDIST_WORKER", "PYTEST_ADDOPTS")


@dataclass(frozen=True)
class UmlResult:
    status: int | None  #: exit status of the command inside (None: never written)
    output: str  #: what the command printed (stdout and stderr)
    console_tail: str  #: last lines of the UML console (kernel messages)
    boot_s: float | None  #: from starting linux.uml to vcan0 up inside [s]
    wall_s: float  #: whole boot, run and halt [s]
    timed_out: bool


def _raise_priority(nice: int) -> Callable[[], None]:
    def pre() -> None:
        with contextlib.suppress(OSError):  # not permitted: run at the normal priority
            os.setpriority(os.PRIO_PROCESS, 0, nice)
    return pre


def run_in_uml(command: list[str], workdir: Path, timeout_s: float, *, mem: str = "1G",
               extra_env: dict[str, str] | None = None, cwd: Path = ROOT, nice: int = -15) -> UmlResult:
    """Boot user-mode-linux, bring vcan0 up inside, run ``command`` there, halt.

    ``workdir`` (on the host file system, visible inside) receives the init
    script, the shim, ``inner.log`` and ``status``. The UML process group is
    killed on timeout and in any case before returning. UML's processes run
    at host priority ``nice`` (where permitted): its single guest CPU is a
    pair of host processes that hand over to each other at every system call,
    and any host task that gets in between stalls the whole guest (SYNC
    included) for a scheduler slice.
    """
    workdir = Path(workdir).resolve()
    workdir.mkdir(parents=True, exist_ok=True)
    for f in ("status", "inner.log", "booted"):
        (workdir / f).unlink(missing_ok=True)
    shim = build_shim(workdir)
    precompile(cwd)
    env = {k: v for k, v in os.environ.items() if k not in _ENV_DROP and k.isidentifier()}
    env[INSIDE_ENV] = "1"
    env.update(extra_env or {})
    init = _init_script(workdir, command, env, cwd)
    umldir = workdir / "uml"
    umldir.mkdir(exist_ok=True)
    host_env = dict(os.environ, LD_PRELOAD=str(shim))
    argv = [_which(UML_KERNEL), f"mem={mem}", "rootfstype=hostfs", "rootflags=/", "rw", f"init={init}",
            "con=null", "con0=fd:0,fd:1", "quiet", f"uml_dir={umldir}"]
    console = workdir / "console.log"
    t0 = time.monotonic()
    start_epoch = time.time()
    timed_out = False
    with open(console, "wb") as con:
        proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=con, stderr=subprocess.STDOUT,
                                env=host_env, start_new_session=True, preexec_fn=_raise_priority(nice))
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            timed_out = True
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGKILL)  # the UML kernel's helper and guest processes
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=10)
    wall = time.monotonic() - t0
    st = workdir / "status"
    status = int(st.read_text().strip()) if st.exists() and st.read_text().strip() else None
    booted = workdir / "booted"
    boot_s = None
    if booted.exists():
        try:
            boot_s = float(booted.read_text()) - start_epoch
        except ValueError:
            boot_s = None
    out = (workdir / "inner.log").read_text(errors="replace") if (workdir / "inner.log").exists() else ""
    tail = "\n".join(console.read_text(errors="replace").splitlines()[-25:])
    return UmlResult(status, out, tail, boot_s, wall, timed_out)


def stage_mode() -> tuple[str, str | None]:
    """How the stage can run here: ("host", None), ("uml", None) or ("skip", reason)."""
    ok, why = host_vcan()
    if ok:
        return "host", None
    if inside_uml():
        return "skip", f"inside user-mode-linux but {CHANNEL} is not usable: {why}"
    missing = uml_problem()
    if missing is None:
        return "uml", why
    return "skip", f"no vcan in this kernel ({why}) and {missing}"
