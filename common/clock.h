/* clock: monotonic time for stage timings and progress. */
#ifndef LC_CLOCK_H
#define LC_CLOCK_H
#include <time.h>

/* Milliseconds on CLOCK_MONOTONIC (an arbitrary origin: subtract two readings). */
static inline double lc_clock_ms(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

#endif
