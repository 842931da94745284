/*
 * LD_PRELOAD shim for Debian's user-mode-linux 6.1 (linux.uml) on hosts whose
 * XSAVE area is larger than UML's compiled-in `struct _xstate` (832 bytes:
 * x87/SSE, header, AVX). Such hosts (AVX-512, AMX) refuse UML's
 * PTRACE_SETREGSET(NT_X86_XSTATE) with EFAULT ("ptrace set fp regs failed",
 * kernel panic at the first process), because the kernel accepts only a whole
 * buffer of its own size. Without xstate, UML's fallback (PTRACE_SETFPREGS)
 * loses the upper vector registers of every guest process at each page fault
 * (the fault goes through a signal handler in the guest's host process), and
 * glibc's AVX string functions, numpy and numba then misbehave.
 *
 * The shim widens both calls: GETREGSET fetches the host's whole area, hands
 * UML its first bytes and keeps the whole area per UML buffer (one buffer per
 * guest task); SETREGSET writes UML's bytes over the kept area of that buffer
 * (or over the live state when none is kept) and sets the whole area. Every
 * other ptrace request passes through unchanged.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ptrace.h>
#include <sys/types.h>
#include <sys/uio.h>

#define NT_XSTATE 0x202
#define FULL_MAX 65536
#define SLOTS 4096

typedef long (*ptrace_fn)(int, pid_t, void *, void *);
static ptrace_fn real_ptrace;
static unsigned char scratch[FULL_MAX];
static size_t full_len;
static struct { void *key; unsigned char *buf; } kept[SLOTS];

static unsigned slot_of(void *key)
{
    return (unsigned)((((uintptr_t)key) >> 4) * 2654435761u) % SLOTS;
}

static long get_full(pid_t pid)
{
    struct iovec io = { scratch, FULL_MAX };
    long r = real_ptrace(PTRACE_GETREGSET, pid, (void *)NT_XSTATE, &io);
    if (r >= 0)
        full_len = io.iov_len;
    return r;
}

long ptrace(enum __ptrace_request req, ...)
{
    va_list ap;
    va_start(ap, req);
    pid_t pid = va_arg(ap, pid_t);
    void *addr = va_arg(ap, void *);
    void *data = va_arg(ap, void *);
    va_end(ap);
    if (!real_ptrace)
        real_ptrace = (ptrace_fn)dlsym(RTLD_NEXT, "ptrace");
    if ((req == PTRACE_GETREGSET || req == PTRACE_SETREGSET) && (uintptr_t)addr == NT_XSTATE && data) {
        struct iovec *iov = data;
        unsigned s = slot_of(iov->iov_base);
        if (req == PTRACE_GETREGSET) {
            long r = get_full(pid);
            if (r < 0)
                return r;
            size_t n = iov->iov_len < full_len ? iov->iov_len : full_len;
            memcpy(iov->iov_base, scratch, n);
            iov->iov_len = n;
            if (!kept[s].buf)
                kept[s].buf = malloc(FULL_MAX);
            if (kept[s].buf) {
                kept[s].key = iov->iov_base;
                memcpy(kept[s].buf, scratch, full_len);
            }
            return r;
        }
        if (!full_len || iov->iov_len < full_len) {
            if (full_len && kept[s].buf && kept[s].key == iov->iov_base) {
                memcpy(scratch, kept[s].buf, full_len);
            } else {
                long r = get_full(pid);
                if (r < 0)
                    return r;
            }
            size_t n = iov->iov_len < full_len ? iov->iov_len : full_len;
            memcpy(scratch, iov->iov_base, n);
            struct iovec io = { scratch, full_len };
            return real_ptrace(PTRACE_SETREGSET, pid, addr, &io);
        }
    }
    return real_ptrace(req, pid, addr, data);
}
