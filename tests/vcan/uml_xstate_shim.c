/* LD_PRELOAD shim for user-mode Linux on hosts with a large XSAVE area (AVX-512, AMX).
 *
 * UML saves and restores a guest process's FP state with PTRACE_{GET,SET}REGSET(NT_X86_XSTATE)
 * on a buffer sized for x87/SSE/AVX. The host kernel truncates a short GET but refuses a SET
 * whose size is not its full user XSAVE size (EFAULT): on an AMX host every guest process dies
 * at its first context switch ("ptrace set fp regs failed, errno = 14"). Here both calls go
 * through a full-size buffer: a GET copies back what the caller asked for; a SET takes the
 * components that lie wholly inside the caller's buffer from it and leaves the others (AVX-512,
 * PKRU, AMX) as the target has them. Calls with a full-size buffer pass through untouched.
 *
 * UML reads a stopped process's state and writes it back at every guest system call; on these
 * hosts the full-size SET is slow (20,000 guest stat() calls: 16.7 s), so a SET that writes back
 * exactly what was read, with the target not run since, is skipped (1.2 s).
 */
#define _GNU_SOURCE
#include <cpuid.h>
#include <dlfcn.h>
#include <elf.h>
#include <stdarg.h>
#include <stdint.h>
#include <string.h>
#include <sys/ptrace.h>
#include <sys/types.h>
#include <sys/uio.h>

typedef long (*ptrace_fn)(enum __ptrace_request, ...);

#define XSTATE_BV_OFFSET 512
static unsigned char full_state[1 << 16] __attribute__((aligned(64)));

/* Bits of the XSTATE_BV components that lie wholly within the first `n` bytes (standard format). */
static uint64_t components_within(size_t n) {
    uint64_t mask = 0x3;   /* x87 and SSE: the legacy area */
    for (unsigned i = 2; i < 63; i++) {
        unsigned size, offset, c, d;
        if (!__get_cpuid_count(0xd, i, &size, &offset, &c, &d) || size == 0)
            continue;
        if ((size_t)offset + size <= n)
            mask |= 1ULL << i;
    }
    return mask;
}

/* The last full state read, valid until its target may have run (any request that is not a
 * register or memory access of a stopped tracee). */
static pid_t cached_pid;
static size_t cached_len;

static int keeps_target_stopped(enum __ptrace_request request) {
    switch (request) {
    case PTRACE_PEEKTEXT: case PTRACE_PEEKDATA: case PTRACE_PEEKUSER: case PTRACE_POKETEXT:
    case PTRACE_POKEDATA: case PTRACE_POKEUSER: case PTRACE_GETREGS: case PTRACE_SETREGS:
    case PTRACE_GETFPREGS: case PTRACE_SETFPREGS: case PTRACE_GETSIGINFO: case PTRACE_GETEVENTMSG:
        return 1;
    default:
        return 0;
    }
}

long ptrace(enum __ptrace_request request, ...) {
    va_list ap;
    va_start(ap, request);
    pid_t pid = va_arg(ap, pid_t);
    void *addr = va_arg(ap, void *);
    void *data = va_arg(ap, void *);
    va_end(ap);
    static ptrace_fn real;
    if (!real)
        real = (ptrace_fn)dlsym(RTLD_NEXT, "ptrace");
    if ((request != PTRACE_GETREGSET && request != PTRACE_SETREGSET) || (uintptr_t)addr != NT_X86_XSTATE || !data) {
        if (!keeps_target_stopped(request))
            cached_pid = 0;
        return real(request, pid, addr, data);
    }
    struct iovec *caller = data;
    struct iovec full = {full_state, sizeof full_state};
    if (request == PTRACE_SETREGSET && pid == cached_pid) {
        full.iov_len = cached_len;    /* the target has not run since its state was read */
    } else {
        cached_pid = 0;
        if (real(PTRACE_GETREGSET, pid, addr, &full) < 0)
            return real(request, pid, addr, data);
        cached_pid = pid;
        cached_len = full.iov_len;
    }
    if (caller->iov_len >= full.iov_len)
        return real(request, pid, addr, data);
    if (request == PTRACE_SETREGSET && pid == cached_pid && memcmp(full_state, caller->iov_base, caller->iov_len) == 0)
        return 0;   /* writing back what was read: nothing to do */
    size_t n = caller->iov_len;
    if (request == PTRACE_GETREGSET) {
        memcpy(caller->iov_base, full_state, n);
        return 0;
    }
    uint64_t target_bv, caller_bv;
    memcpy(&target_bv, full_state + XSTATE_BV_OFFSET, sizeof target_bv);
    memcpy(full_state, caller->iov_base, n);
    if (n >= XSTATE_BV_OFFSET + sizeof caller_bv) {
        uint64_t mine = components_within(n);
        memcpy(&caller_bv, full_state + XSTATE_BV_OFFSET, sizeof caller_bv);
        caller_bv = (caller_bv & mine) | (target_bv & ~mine);
        memcpy(full_state + XSTATE_BV_OFFSET, &caller_bv, sizeof caller_bv);
    }
    long result = real(PTRACE_SETREGSET, pid, addr, &full);
    if (result < 0)
        cached_pid = 0;
    return result;
}
