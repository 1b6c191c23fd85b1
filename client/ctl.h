/* lucentctl internals shared by the command files (lucentctl.c: main, global options and
 * dispatch; ctl_common.c: connection and output helpers; ctl_scene.c: ping, state, send,
 * light/object/material/env/settings; ctl_script.c: script; ctl_stream.c: watch, snapshot,
 * latency; ctl_mr.c: mr replay; ctl_load.c: load). Every command takes (argc, argv) with argv[0] = the command name and returns
 * an exit code. */
#ifndef LC_CTL_H
#define LC_CTL_H
#include <cjson/cJSON.h>
#include <stdio.h>

#include "lucent_client.h"

enum { CTL_EXIT_OK = 0, CTL_EXIT_REFUSED = 1, CTL_EXIT_USAGE = 2, CTL_EXIT_CONN = 3 };
#define CTL_TIMEOUT_MS 5000

/* Global options, set by main before dispatch. */
extern const char *ctl_url;     /* --url / LUCENT_URL */
extern const char *ctl_token;   /* --token / LUCENT_TOKEN */
extern int ctl_json;            /* --json */
extern int ctl_insecure;        /* --insecure: wss with self-signed / mismatched certificates */
extern const char *ctl_ca_file; /* --ca-file / LUCENT_CA_FILE: PEM bundle for wss (NULL = system) */

/* Prints "lucentctl: <message>" and the hint to stderr; returns CTL_EXIT_USAGE. */
int ctl_usage_error(const char *fmt, ...);
/* 1 when argv[1..argc) contains --help or -h. */
int ctl_wants_help(int argc, char **argv);

/* Connects with ctl_url/ctl_token (opts may be NULL: defaults, no reconnect). On failure
 * prints the reason and sets *rc to CTL_EXIT_REFUSED (server refused) or CTL_EXIT_CONN. */
lc_client *ctl_connect(const lc_client_options *opts, int *rc);

/* Prints a server `error` reply as a clear one-line message (code, field, hint) on stderr. */
void ctl_print_server_error(const char *reply_json);

/* Parses "x,y,z" style lists of exactly n finite numbers. Returns 0 or -1. */
int ctl_parse_floats(const char *s, double *out, int n);

/* The script parser without playing (ctl_script.c; the fuzz target's entry): reads JSON
 * Lines from f, reports malformed lines as NAME:LINE: on stderr. *messages = valid messages,
 * *errors = malformed lines. Returns 0, or -1 when f cannot be read or memory runs out. */
int ctl_script_validate(FILE *f, const char *name, size_t *messages, long *errors);

/* Streaming commands (ctl_stream.c). */
int ctl_cmd_watch(int argc, char **argv);
int ctl_cmd_snapshot(int argc, char **argv);
int ctl_cmd_latency(int argc, char **argv);

/* Load test (ctl_load.c): N viewers on one libwebsockets context, one controller. */
int ctl_cmd_load(int argc, char **argv);

/* MR sessions (ctl_mr.c): mr replay DIR. */
int ctl_cmd_mr(int argc, char **argv);

/* --- helpers added for the command files (ctl_common.c) -------------------------------- */

/* Parses one finite number; the whole string must be consumed. Returns 0 or -1. */
int ctl_parse_double(const char *s, double *out);
/* Parses a whole decimal integer in [lo, hi]. Returns 0 or -1. */
int ctl_parse_int(const char *s, long long lo, long long hi, long long *out);
/* Parses true|false (also 1|0, yes|no, on|off). Returns 0 or -1. */
int ctl_parse_bool(const char *s, int *out);
/* Parses a comma list of 1..max finite numbers into out; *n gets the count. Returns 0 or -1. */
int ctl_parse_float_list(const char *s, double *out, int max, int *n);

/* Writes "server error CODE at POINTER: message (hint: ...)" for an `error` reply into buf
 * (always terminated). Every code of PROTOCOL.md §5.2 has its own hint. */
void ctl_format_server_error(const char *reply_json, char *buf, size_t buflen);
/* The hint for an error code (never NULL). */
const char *ctl_error_hint(const char *code);
/* The reply's "revision", or -1 when it has none. */
long long ctl_reply_revision(const char *reply_json);

/* Sends one request and waits for its reply. Returns CTL_EXIT_OK with the reply text in
 * *reply (malloc'd; the caller frees; reply may be NULL), CTL_EXIT_REFUSED after printing
 * the server error (and, with --json, the reply on stdout), or CTL_EXIT_CONN after printing
 * the connection failure. */
int ctl_request(lc_client *c, const char *json, char **reply);

/* Prints JSON text: compact with --json (or when compact is set), else indented. */
void ctl_print_json(const char *json, int compact);

/* One flag of a command that builds a JSON object (table-driven parsing and --help). */
typedef enum {
    CTL_FLAG_NUM,    /* one finite number */
    CTL_FLAG_INT,    /* one integer */
    CTL_FLAG_BOOL,   /* true|false */
    CTL_FLAG_LIST,   /* comma list of numbers; counts allowed by `counts` (bit n = n values) */
    CTL_FLAG_CHOICE, /* one of `choices` ("a|b|c") */
    CTL_FLAG_STRING, /* any string (1..256 bytes) */
    CTL_FLAG_SWITCH, /* no value; sets key to true */
} ctl_flag_kind;

typedef struct ctl_flag {
    const char *name; /* "--position"; NULL ends the table */
    const char *key;  /* JSON field it sets */
    ctl_flag_kind kind;
    unsigned long counts; /* LIST: allowed counts as bits (1ul << 3 = exactly 3) */
    int expand;           /* LIST: a single value is repeated to the largest allowed count */
    const char *choices;  /* CHOICE */
    const char *metavar;  /* shown in help and errors, e.g. "x,y,z" */
    const char *help;
} ctl_flag;

/* Parses argv[start..argc) against the table into `into` (fields added by key); the other
 * arguments go to positional[] (at most max_pos; "--" ends the flags). A flag's value is
 * the next argument (so negative numbers work) or "--flag=value". Returns 0 with *n_pos set,
 * or CTL_EXIT_USAGE after printing an error that names the flag and value (`cmd` prefixes
 * it, e.g. "light set"). */
int ctl_parse_flags(const char *cmd, const ctl_flag *table, int argc, char **argv, int start, cJSON *into,
                    char **positional, int max_pos, int *n_pos);
/* Prints "  --name METAVAR  help" lines for the table. */
void ctl_print_flags(const ctl_flag *table, FILE *out);

/* Scene and scripting commands (ctl_scene.c, ctl_script.c). */
int ctl_cmd_ping(int argc, char **argv);
int ctl_cmd_state(int argc, char **argv);
int ctl_cmd_send(int argc, char **argv);
int ctl_cmd_light(int argc, char **argv);
int ctl_cmd_object(int argc, char **argv);
int ctl_cmd_material(int argc, char **argv);
int ctl_cmd_env(int argc, char **argv);
int ctl_cmd_settings(int argc, char **argv);
int ctl_cmd_script(int argc, char **argv);

#endif
