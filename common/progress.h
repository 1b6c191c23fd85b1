/* progress: a progress bar on a terminal, plain lines (every 10%) otherwise.
 * Thread-safe: workers call lc_progress_add() from any thread. Output goes to stderr. */
#ifndef LC_PROGRESS_H
#define LC_PROGRESS_H
#include <stdint.h>

typedef struct lc_progress lc_progress;

/* Global switch (e.g. --quiet): when off, begin() returns a handle that prints nothing. */
void lc_progress_set_enabled(int enabled);
lc_progress *lc_progress_begin(const char *stage, uint64_t total);
void lc_progress_add(lc_progress *p, uint64_t done); /* NULL-safe */
/* Ends the stage and frees the handle; prints elapsed seconds. NULL-safe. */
void lc_progress_end(lc_progress *p);

#endif
