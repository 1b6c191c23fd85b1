#include "util/opt.h"

#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"

const lc_opt *lc_opt_find(const lc_opt *table, const char *name) {
    for (const lc_opt *o = table; o->name; o++)
        if (strcmp(o->name, name) == 0) return o;
    return NULL;
}

static int opt_enum_index(const char *choices, const char *value) {
    size_t vlen = strlen(value);
    int index = 0;
    for (const char *p = choices; *p; index++) {
        const char *bar = strchr(p, '|');
        size_t len = bar ? (size_t)(bar - p) : strlen(p);
        if (len == vlen && strncmp(p, value, len) == 0) return index;
        if (!bar) break;
        p = bar + 1;
    }
    return -1;
}

static int opt_parse_bool(const char *v) {
    if (!strcmp(v, "1") || !strcmp(v, "true") || !strcmp(v, "yes") || !strcmp(v, "on")) return 1;
    if (!strcmp(v, "0") || !strcmp(v, "false") || !strcmp(v, "no") || !strcmp(v, "off")) return 0;
    return -1;
}

static int opt_assign(const lc_opt *o, void *settings, const char *value, char *err, size_t errlen) {
    char *field = (char *)settings + o->offset;
    char *end = NULL;
    switch (o->type) {
    case LC_OPT_INT: {
        errno = 0;
        long long v = strtoll(value, &end, 10);
        if (errno || end == value || *end) {
            lc_set_err(err, errlen, "--%s: '%s' is not an integer", o->name, value);
            return -1;
        }
        if ((double)v < o->min || (double)v > o->max) {
            lc_set_err(err, errlen, "--%s: %lld is out of range [%.0f, %.0f]", o->name, v, o->min, o->max);
            return -1;
        }
        *(int *)field = (int)v;
        return 0;
    }
    case LC_OPT_FLOAT: {
        errno = 0;
        double v = strtod(value, &end);
        if (errno || end == value || *end || !isfinite(v)) {
            lc_set_err(err, errlen, "--%s: '%s' is not a finite number", o->name, value);
            return -1;
        }
        if (v < o->min || v > o->max) {
            lc_set_err(err, errlen, "--%s: %g is out of range [%g, %g]", o->name, v, o->min, o->max);
            return -1;
        }
        *(double *)field = v;
        return 0;
    }
    case LC_OPT_BOOL: {
        int v = opt_parse_bool(value);
        if (v < 0) {
            lc_set_err(err, errlen, "--%s: '%s' is not a boolean (true/false)", o->name, value);
            return -1;
        }
        *(int *)field = v;
        return 0;
    }
    case LC_OPT_STRING: {
        size_t len = strlen(value), cap = (size_t)o->max;
        if (len + 1 > cap) {
            lc_set_err(err, errlen, "--%s: value is %zu bytes, the limit is %zu", o->name, len, cap - 1);
            return -1;
        }
        if ((double)len < o->min) {
            lc_set_err(err, errlen, "--%s: value must not be empty", o->name);
            return -1;
        }
        memcpy(field, value, len + 1);
        return 0;
    }
    case LC_OPT_ENUM: {
        int v = opt_enum_index(o->choices, value);
        if (v < 0) {
            lc_set_err(err, errlen, "--%s: '%s' is not one of %s", o->name, value, o->choices);
            return -1;
        }
        *(int *)field = v;
        return 0;
    }
    case LC_OPT_CALLBACK: return o->fn(settings, value, err, errlen);
    }
    lc_set_err(err, errlen, "--%s: unknown option type", o->name);
    return -1;
}

int lc_opt_defaults(const lc_opt *table, void *settings, char *err, size_t errlen) {
    for (const lc_opt *o = table; o->name; o++) {
        if (o->type == LC_OPT_CALLBACK) continue;
        if (!o->def) {
            char *field = (char *)settings + o->offset;
            if (o->type == LC_OPT_FLOAT) *(double *)field = 0;
            else if (o->type == LC_OPT_STRING) field[0] = 0;
            else *(int *)field = 0;
            continue;
        }
        if (opt_assign(o, settings, o->def, err, errlen) != 0) return -1;
    }
    return 0;
}

int lc_opt_set(const lc_opt *table, void *settings, const char *name, const char *value, char *err, size_t errlen) {
    const lc_opt *o = lc_opt_find(table, name);
    if (!o) {
        lc_set_err(err, errlen, "unknown option --%s (see --help)", name);
        return -1;
    }
    return opt_assign(o, settings, value, err, errlen);
}

int lc_opt_parse(const lc_opt *table, void *settings, int argc, char **argv, int start, char **positional,
                 int max_positional, char *err, size_t errlen) {
    int npos = 0, options_done = 0;
    for (int i = start; i < argc; i++) {
        const char *arg = argv[i];
        if (options_done || arg[0] != '-' || arg[1] != '-' || arg[2] == 0) {
            if (!options_done && strcmp(arg, "--") == 0) {
                options_done = 1;
                continue;
            }
            if (arg[0] == '-' && arg[1] && !options_done && arg[1] != '-') {
                lc_set_err(err, errlen, "unknown option '%s' (options are --long; see --help)", arg);
                return -1;
            }
            if (npos >= max_positional) {
                lc_set_err(err, errlen, "unexpected argument '%s' (see --help)", arg);
                return -1;
            }
            positional[npos++] = argv[i];
            continue;
        }
        char name[64];
        const char *eq = strchr(arg + 2, '=');
        size_t nlen = eq ? (size_t)(eq - (arg + 2)) : strlen(arg + 2);
        if (nlen >= sizeof name) {
            lc_set_err(err, errlen, "unknown option '%.40s...'", arg);
            return -1;
        }
        memcpy(name, arg + 2, nlen);
        name[nlen] = 0;
        const lc_opt *o = lc_opt_find(table, name);
        if (!o && strncmp(name, "no-", 3) == 0 && !eq) {
            const lc_opt *b = lc_opt_find(table, name + 3);
            if (b && b->type == LC_OPT_BOOL) {
                *(int *)((char *)settings + b->offset) = 0;
                continue;
            }
        }
        if (!o) {
            lc_set_err(err, errlen, "unknown option --%s (see --help)", name);
            return -1;
        }
        const char *value;
        if (eq) {
            value = eq + 1;
        } else if (o->type == LC_OPT_BOOL) {
            value = "true";
        } else {
            if (i + 1 >= argc) {
                lc_set_err(err, errlen, "--%s needs a value", name);
                return -1;
            }
            value = argv[++i];
        }
        if (opt_assign(o, settings, value, err, errlen) != 0) return -1;
    }
    return npos;
}

void lc_opt_help(const lc_opt *table, FILE *out) {
    for (const lc_opt *o = table; o->name; o++) {
        char left[64];
        const char *meta = o->metavar ? o->metavar
            : o->type == LC_OPT_INT   ? "N"
            : o->type == LC_OPT_FLOAT ? "X"
            : o->type == LC_OPT_ENUM  ? o->choices
            : o->type == LC_OPT_BOOL  ? ""
                                      : "TEXT";
        snprintf(left, sizeof left, "--%s%s%s", o->name, *meta ? " " : "", meta);
        fprintf(out, "  %-30s %s", left, o->help ? o->help : "");
        if (o->def && o->type != LC_OPT_CALLBACK) fprintf(out, " (default %s)", o->def);
        if (o->type == LC_OPT_INT) fprintf(out, " [%.0f..%.0f]", o->min, o->max);
        if (o->type == LC_OPT_FLOAT) fprintf(out, " [%g..%g]", o->min, o->max);
        fputc('\n', out);
    }
}
