#include "util/progress.h"

#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

struct lc_progress {
    char stage[48];
    uint64_t total;
    _Atomic uint64_t done;
    pthread_mutex_t lock; /* guards the printing fields below */
    double start, last_print;
    int last_decile;
    int tty;
};

static int progress_enabled = 1;

void lc_progress_set_enabled(int enabled) { progress_enabled = enabled; }

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + ts.tv_nsec * 1e-9;
}

lc_progress *lc_progress_begin(const char *stage, uint64_t total) {
    if (!progress_enabled) return NULL;
    lc_progress *p = calloc(1, sizeof *p);
    if (!p) return NULL;
    snprintf(p->stage, sizeof p->stage, "%s", stage);
    p->total = total ? total : 1;
    pthread_mutex_init(&p->lock, NULL);
    p->start = p->last_print = now_s();
    p->last_decile = -1;
    p->tty = isatty(STDERR_FILENO);
    return p;
}

static void progress_print(lc_progress *p, uint64_t done, int final) {
    double t = now_s();
    double frac = (double)done / (double)p->total;
    if (frac > 1) frac = 1;
    if (p->tty) {
        if (!final && t - p->last_print < 0.1) return;
        char bar[31];
        int fill = (int)(frac * 30);
        for (int i = 0; i < 30; i++) bar[i] = i < fill ? '#' : '-';
        bar[30] = 0;
        fprintf(stderr, "\r%-22s [%s] %5.1f%% %7.1fs%s", p->stage, bar, frac * 100, t - p->start, final ? "\n" : "");
    } else {
        int decile = (int)(frac * 10);
        if (!final && decile <= p->last_decile) return;
        p->last_decile = decile;
        if (final) fprintf(stderr, "%s: done in %.2fs\n", p->stage, t - p->start);
        else fprintf(stderr, "%s: %d%%\n", p->stage, decile * 10);
    }
    p->last_print = t;
}

void lc_progress_add(lc_progress *p, uint64_t n) {
    if (!p) return;
    uint64_t done = atomic_fetch_add(&p->done, n) + n;
    if (pthread_mutex_trylock(&p->lock) != 0) return; /* someone else is printing */
    progress_print(p, done, 0);
    pthread_mutex_unlock(&p->lock);
}

void lc_progress_end(lc_progress *p) {
    if (!p) return;
    pthread_mutex_lock(&p->lock);
    progress_print(p, p->total, 1);
    pthread_mutex_unlock(&p->lock);
    pthread_mutex_destroy(&p->lock);
    free(p);
}
