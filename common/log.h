/* log: levelled, one line per event, to stderr. Thread-safe (one fprintf per line). */
#ifndef LC_LOG_H
#define LC_LOG_H

typedef enum { LC_LOG_DEBUG = 0, LC_LOG_INFO, LC_LOG_WARN, LC_LOG_ERROR } lc_log_level;

/* The level is one atomic (relaxed): any thread may set it while others log. */
void lc_log_set_level(lc_log_level level);
lc_log_level lc_log_get_level(void);
/* Parses "debug|info|warn|error"; returns -1 when unknown. */
int lc_log_parse_level(const char *name);
void lc_log(lc_log_level level, const char *module, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

#define lc_debug(mod, ...) lc_log(LC_LOG_DEBUG, mod, __VA_ARGS__)
#define lc_info(mod, ...) lc_log(LC_LOG_INFO, mod, __VA_ARGS__)
#define lc_warn(mod, ...) lc_log(LC_LOG_WARN, mod, __VA_ARGS__)
#define lc_error(mod, ...) lc_log(LC_LOG_ERROR, mod, __VA_ARGS__)

/* Error-string helper used across modules: formats into a caller buffer (may be NULL). */
void lc_set_err(char *err, unsigned long errlen, const char *fmt, ...) __attribute__((format(printf, 3, 4)));

#endif
