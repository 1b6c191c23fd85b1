#include "util/log.h"

#include <stdarg.h>
#include <stdatomic.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

/* Atomic because lucentd's service thread sets it on SIGHUP while the compute thread logs;
 * relaxed order is enough: the level guards nothing else, a line may see the old one. */
static _Atomic int log_level = LC_LOG_INFO;

void lc_log_set_level(lc_log_level level) { atomic_store_explicit(&log_level, (int)level, memory_order_relaxed); }
lc_log_level lc_log_get_level(void) { return (lc_log_level)atomic_load_explicit(&log_level, memory_order_relaxed); }

int lc_log_parse_level(const char *name) {
    static const char *names[] = {"debug", "info", "warn", "error"};
    for (int i = 0; i < 4; i++)
        if (strcmp(name, names[i]) == 0) return i;
    return -1;
}

void lc_log(lc_log_level level, const char *module, const char *fmt, ...) {
    if ((int)level < atomic_load_explicit(&log_level, memory_order_relaxed)) return;
    static const char *tags[] = {"debug", "info", "warn", "error"};
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    struct tm tm;
    gmtime_r(&ts.tv_sec, &tm);
    /* One fprintf per line so concurrent threads never interleave within a line. */
    fprintf(stderr, "%04d-%02d-%02dT%02d:%02d:%02d.%03ldZ %-5s %s: %s\n", tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday,
            tm.tm_hour, tm.tm_min, tm.tm_sec, ts.tv_nsec / 1000000, tags[level], module, msg);
}

void lc_set_err(char *err, unsigned long errlen, const char *fmt, ...) {
    if (!err || errlen == 0) return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err, errlen, fmt, ap);
    va_end(ap);
}
