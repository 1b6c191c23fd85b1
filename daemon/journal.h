/* journal: durability of the dynamic state. Every accepted change is appended to
 * DIR/journal.log as one JSON line {"type":"batch","revision":N,"ops":[...]} and fsync'd
 * before the client's `ok` (mode always) or within a second (everysec). Compaction writes
 * DIR/snapshot.json (a `state` message, atomically: temp + fsync + rename) and then empties
 * the journal; a crash between the two only leaves journal lines the snapshot already
 * holds, which replay skips by revision. A torn last line (crash mid-append) is cut off.
 * Thread: the service thread only. */
#ifndef LC_JOURNAL_H
#define LC_JOURNAL_H
#include <stddef.h>
#include <stdint.h>

#include "state.h"

typedef enum { LC_FSYNC_ALWAYS = 0, LC_FSYNC_EVERYSEC = 1 } lc_fsync_mode;

typedef struct lc_journal lc_journal;

/* Opens DIR (created if missing) and restores *state (already initialised from the bake):
 * the snapshot, then every journal line newer than it. Returns NULL with err naming the
 * file and line on a corrupt snapshot or journal (the daemon then refuses to start rather
 * than lose acknowledged changes). */
lc_journal *lc_journal_open(const char *dir, lc_fsync_mode mode, lc_state *state, char *err, size_t errlen);
/* Appends one accepted change with its revision. Returns 0 when durable per the mode. */
int lc_journal_append(lc_journal *j, const lc_proto_op *ops, uint32_t n_ops, uint64_t revision, char *err,
                      size_t errlen);
/* everysec mode: fsyncs pending appends once a second has passed. Call from the loop. */
void lc_journal_tick(lc_journal *j);
/* Snapshot + truncate. */
int lc_journal_compact(lc_journal *j, const lc_state *state, char *err, size_t errlen);
/* Bytes in journal.log (the daemon compacts past a threshold). */
uint64_t lc_journal_bytes(const lc_journal *j);
/* Flushes and closes. NULL-safe. */
void lc_journal_close(lc_journal *j);

#endif
