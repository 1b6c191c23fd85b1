/* A flag a signal handler sets and other code polls. A lock-free atomic rather than
 * `volatile sig_atomic_t`: C11 (7.14.1.1) lets a handler store to it, and the kernel may run the
 * handler on any thread that does not block the signal (an engine worker, a viewer thread),
 * where a plain sig_atomic_t read by the main thread is a data race (ThreadSanitizer saw
 * lucentd's stop flag written from an engine worker). */
#ifndef LC_SIGFLAG_H
#define LC_SIGFLAG_H

#include <stdatomic.h>

_Static_assert(ATOMIC_INT_LOCK_FREE == 2, "signal flags need a lock-free atomic int");

typedef atomic_int lc_sigflag;

#endif
