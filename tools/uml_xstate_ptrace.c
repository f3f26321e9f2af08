/*
 * uml_xstate_ptrace.c: lets User-Mode Linux boot on hosts whose XSAVE area is larger
 * than the buffer UML hands to ptrace (CPUs with AMX, for one).
 *
 * UML saves and restores each of its processes' FPU state with
 * ptrace(PTRACE_GETREGSET / PTRACE_SETREGSET, pid, NT_X86_XSTATE, iov). Debian 12's UML
 * (6.1) passes a buffer of a size fixed when it was built. The host kernel truncates a GET
 * to that size, but refuses a SET that is not the whole XSAVE area with EFAULT, and UML
 * panics ("userspace - ptrace set fp regs failed, errno = 14"). Newer UML kernels size the
 * buffer at run time; Debian 12 has none.
 *
 * Loaded into linux.uml with LD_PRELOAD, this ptrace() bounces NT_X86_XSTATE requests whose
 * buffer is smaller than the host's XSAVE area through one of the full size:
 *   GET: read the full state, hand UML its part;
 *   SET: read the full state, overlay UML's part, write the whole area back.
 * The state beyond UML's part is then not saved per process by UML: what runs inside UML
 * must keep off the registers kept there (tools/uml_run.py turns off AVX-512 in glibc,
 * numpy and OpenBLAS inside UML for that reason). Every other request goes to libc as is.
 *
 * HIL_UML_XSTATE_LOG=PATH appends one line per distinct (request, UML size, host size)
 * seen, for diagnosis (tools/uml_run.py --xstate-report).
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ptrace.h>
#include <sys/types.h>
#include <sys/uio.h>

#ifndef NT_X86_XSTATE
#define NT_X86_XSTATE 0x202
#endif

/* Larger than any XSAVE area an x86 CPU defines today (AMX: about 11 KiB). */
#define PROBE_SIZE (64 * 1024)

typedef long (*ptrace_fn)(enum __ptrace_request, pid_t, void *, void *);

static ptrace_fn real_ptrace(void)
{
    static ptrace_fn real;
    if (!real)
        real = (ptrace_fn)dlsym(RTLD_NEXT, "ptrace");
    return real;
}

/* One full-size buffer per thread, allocated at first use (a large __thread array would
 * not fit the static TLS a preloaded library gets). */
static __thread unsigned char *bounce;

/* Reads pid's whole XSAVE area into the bounce buffer; returns its size, or -1 (errno set). */
static long read_full(pid_t pid)
{
    if (!bounce && !(bounce = malloc(PROBE_SIZE))) {
        errno = ENOMEM;
        return -1;
    }
    struct iovec full = {bounce, PROBE_SIZE};
    if (real_ptrace()(PTRACE_GETREGSET, pid, (void *)NT_X86_XSTATE, &full) < 0)
        return -1;
    return (long)full.iov_len;
}

static void log_once(enum __ptrace_request request, size_t uml_size, long host_size)
{
    static int logged[2];
    const char *path = getenv("HIL_UML_XSTATE_LOG");
    int slot = request == PTRACE_SETREGSET;
    if (!path || logged[slot])
        return;
    logged[slot] = 1;
    FILE *log = fopen(path, "a");
    if (log) {
        fprintf(log, "%s uml_size=%zu host_size=%ld bounced=%d\n",
                slot ? "SETREGSET" : "GETREGSET", uml_size, host_size,
                host_size > 0 && (size_t)host_size > uml_size);
        fclose(log);
    }
}

static long xstate(enum __ptrace_request request, pid_t pid, struct iovec *uml)
{
    static long host_size;          /* the host's XSAVE size: fixed at the host's boot */
    int saved = errno;
    if (!host_size && (host_size = read_full(pid)) < 0) {
        host_size = 0;
        return -1;
    }
    log_once(request, uml->iov_len, host_size);
    errno = saved;
    if ((size_t)host_size <= uml->iov_len)          /* UML's buffer holds it all */
        return real_ptrace()(request, pid, (void *)NT_X86_XSTATE, uml);
    if (read_full(pid) < 0)
        return -1;
    if (request == PTRACE_GETREGSET) {
        memcpy(uml->iov_base, bounce, uml->iov_len);
        return 0;
    }
    memcpy(bounce, uml->iov_base, uml->iov_len);
    struct iovec full = {bounce, (size_t)host_size};
    return real_ptrace()(PTRACE_SETREGSET, pid, (void *)NT_X86_XSTATE, &full);
}

long ptrace(enum __ptrace_request request, ...)
{
    va_list args;
    va_start(args, request);
    pid_t pid = va_arg(args, pid_t);
    void *addr = va_arg(args, void *);
    void *data = va_arg(args, void *);
    va_end(args);
    if ((request == PTRACE_GETREGSET || request == PTRACE_SETREGSET)
        && (unsigned long)addr == NT_X86_XSTATE && data)
        return xstate(request, pid, (struct iovec *)data);
    return real_ptrace()(request, pid, addr, data);
}
