/* opt: a table of settings (name, type, bounds, default, help) that drives command-line
 * parsing, config-file parsing, validation and --help, as Redis' config table does.
 * Values live in a caller struct at each entry's offset; strings are inline char arrays. */
#ifndef LC_OPT_H
#define LC_OPT_H
#include <stddef.h>
#include <stdio.h>

typedef enum {
    LC_OPT_INT,      /* int; bounds [min, max] */
    LC_OPT_FLOAT,    /* double; bounds [min, max], finite */
    LC_OPT_BOOL,     /* int 0/1; "--name" sets, "--no-name" clears, or =true/false/1/0 */
    LC_OPT_STRING,   /* char[(size_t)max]; min = minimum length */
    LC_OPT_ENUM,     /* int index into choices "a|b|c" */
    LC_OPT_CALLBACK, /* repeatable; fn(settings, value) does the work */
} lc_opt_type;

typedef int (*lc_opt_callback)(void *settings, const char *value, char *err, size_t errlen);

typedef struct lc_opt {
    const char *name; /* flag without the leading "--"; NULL ends the table */
    lc_opt_type type;
    size_t offset;
    double min, max;
    const char *def; /* default as text, NULL = none (zero / empty) */
    const char *choices;
    const char *help;
    const char *metavar; /* shown in --help, e.g. "N" or "PATH" */
    lc_opt_callback fn;
} lc_opt;

/* Applies every default. Returns 0, or -1 with err set (a table bug). */
int lc_opt_defaults(const lc_opt *table, void *settings, char *err, size_t errlen);
/* Sets one option from text, validating type and bounds. err names the option.
 * Returns 0, or -1 (unknown name, bad value). */
int lc_opt_set(const lc_opt *table, void *settings, const char *name, const char *value, char *err, size_t errlen);
/* Parses argv[start..argc). Options may appear anywhere ("--" ends them); the others are
 * returned in positional[] (pointers into argv), at most max_positional.
 * Returns the number of positional arguments, or -1 with err set. */
int lc_opt_parse(const lc_opt *table, void *settings, int argc, char **argv, int start, char **positional,
                 int max_positional, char *err, size_t errlen);
/* Prints "  --name METAVAR  help (default X; range [a, b])" lines. */
void lc_opt_help(const lc_opt *table, FILE *out);
const lc_opt *lc_opt_find(const lc_opt *table, const char *name);

#endif
