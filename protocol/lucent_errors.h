/* lucent_errors: the catalogue of lucent/1 error codes (PROTOCOL.md §5.2), one X-macro list
 * that every producer (the parser, the state, lucentd), /metrics, the JSON Schema
 * (schema/defs.json errorCode) and the spec's table follow; tests/unit/proto/
 * check_error_catalogue.py checks that the schema and the table agree with it.
 * X(ID, "code", "meaning", "connection") — the last two are the spec table's columns. */
#ifndef LUCENT_ERRORS_H
#define LUCENT_ERRORS_H

#define LC_PROTO_ERRORS(X)                                                                                            \
    X(BAD_JSON, "bad_json", "not JSON, or not an object", "stays")                                                    \
    X(BAD_UTF8, "bad_utf8", "text frame is not valid UTF-8 (no `id`: the frame is not parsed)",                       \
      "the server sends this `error`, then closes (1007)")                                                            \
    X(TOO_LARGE, "too_large", "message over the size limit", "closes (1009)")                                         \
    X(TOO_DEEP, "too_deep", "nesting over the depth limit", "stays")                                                  \
    X(HELLO_REQUIRED, "hello_required", "first message was not `hello`", "closes (1008)")                             \
    X(UNAUTHORIZED, "unauthorized", "unknown token", "closes (1008)")                                                 \
    X(UNKNOWN_TYPE, "unknown_type", "`type` missing or unknown", "stays")                                             \
    X(INVALID, "invalid", "a field has the wrong type, is missing, or a string is too long", "stays")                 \
    X(OUT_OF_RANGE, "out_of_range", "a number is not finite or outside its range", "stays")                           \
    X(FORBIDDEN, "forbidden", "the role may not do this", "stays")                                                    \
    X(UNKNOWN_ID, "unknown_id", "remove of a light/object that does not exist", "stays")                              \
    X(UNKNOWN_ASSET, "unknown_asset", "asset name not in the scene", "stays")                                         \
    X(UNKNOWN_MATERIAL, "unknown_material", "material name not in the scene", "stays")                                \
    X(LIMIT_EXCEEDED, "limit_exceeded", "too many lights / objects / batch ops", "stays")                             \
    X(RATE_LIMITED, "rate_limited",                                                                                   \
      "over the request rate (or, for `hello`, too many failed hellos from the address, §3.2)",                       \
      "stays (after `hello`: closes 1008)")                                                                           \
    X(BINARY_NOT_ALLOWED, "binary_not_allowed", "client sent a binary frame", "stays")                                \
    X(FRAME_INVALID, "frame_invalid", "an MR upload frame is malformed (the pointer names the field, §8.4)", "stays") \
    X(FRAME_TOO_LARGE, "frame_too_large", "an MR upload frame over the session's `max_frame` (§8.5)", "stays")        \
    X(MR_NOT_ENABLED, "mr_not_enabled",                                                                               \
      "`mr.begin` without the `mr` capability, or an upload frame outside an MR session (§8)", "stays")               \
    X(READ_ONLY, "read_only",                                                                                         \
      "a cluster replica (§9) that cannot reach its change log, or has not caught up with it yet, refuses changes; " \
      "reads and frames keep working: retry later or on another replica",                                             \
      "stays")                                                                                                        \
    X(INTERNAL, "internal",                                                                                           \
      "server fault (logged); also sent without `id` to every client when the relight of an acknowledged "            \
      "revision failed (the message names the revision; `/healthz` answers 503 until a relight succeeds)",            \
      "stays")

typedef enum {
#define LC_PROTO_ERROR_ENUM(id, code, meaning, connection) LC_ERR_##id,
    LC_PROTO_ERRORS(LC_PROTO_ERROR_ENUM)
#undef LC_PROTO_ERROR_ENUM
        LC_ERR_COUNT
} lc_proto_errcode;

/* The code as on the wire ("bad_json"); "internal" for a value outside the catalogue. */
const char *lc_proto_errcode_name(lc_proto_errcode c);
/* The catalogue entry named `code`, or -1. */
int lc_proto_errcode_find(const char *code);
/* The spec table's columns of entry c (for tests and documentation). */
const char *lc_proto_errcode_meaning(lc_proto_errcode c);
const char *lc_proto_errcode_connection(lc_proto_errcode c);

#endif
