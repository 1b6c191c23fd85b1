/* limits: the one source of lucent/1's default limits and lucentd's bounds. The option
 * table (config.c), the protocol parser (lc_proto_default_limits), the engine's validation
 * and the welcome message take their numbers from here, and a test checks that
 * protocol/PROTOCOL.md and protocol/asyncapi.yaml state the same (check_spec_limits.py). */
#ifndef LC_LIMITS_H
#define LC_LIMITS_H

#define LC_LIMIT_STR_(x) #x
#define LC_LIMIT_STR(x) LC_LIMIT_STR_(x) /* a limit as the option table's default string */

#define LC_DEFAULT_PORT 7700          /* lucentd's TCP port */
#define LC_LIMIT_MESSAGE 65536        /* default largest text message (bytes) */
#define LC_LIMIT_MESSAGE_MAX 16777216 /* the most --max-message may be */
#define LC_LIMIT_DEPTH 16             /* default deepest JSON nesting */
#define LC_LIMIT_BATCH 64             /* default ops per batch */
#define LC_LIMIT_BATCH_MAX 4096       /* the most --max-batch may be */
#define LC_LIMIT_LIGHTS 1024          /* lights held: the default and the most the engine takes */
#define LC_LIMIT_OBJECTS 4096         /* object instances: the default and the engine's most */
#define LC_LIMIT_RATE 100             /* default requests per second per connection (burst 2x) */

#endif
