/* lucentd --cluster's URL (lc_cluster_parse_url, cluster.h): what parses, what each field
 * gets, and the error named for each malformed part; the replay of the fuzz corpus covers the
 * rest (tests/fuzz/fuzz_clusterurl.c). The replicas themselves: tests/integration/daemon_cluster.py. */
#include <string.h>

#include "check.h"
#include "cluster.h"

static int parses(const char *url, lc_cluster_url *u, char *err, size_t errlen) {
    return lc_cluster_parse_url(url, strlen(url), u, err, errlen) == 0;
}

static void check_refused(const char *url, const char *says) {
    lc_cluster_url u;
    char err[400] = "";
    int ok = parses(url, &u, err, sizeof err);
    CHECK(!ok && strstr(err, says), "'%s' refused, the error says '%s': %s", url, says, err);
}

int main(void) {
    lc_cluster_url u;
    char err[400];
    CHECK(parses("redis://127.0.0.1:6380/lucent", &u, err, sizeof err), "plain URL: %s", err);
    CHECK(!strcmp(u.host, "127.0.0.1") && u.port == 6380 && !strcmp(u.key, "lucent") && !u.user[0] && !u.password[0],
          "plain URL fields: %s %d %s", u.host, u.port, u.key);
    CHECK(parses("redis://redis.example/scenes/hall-1", &u, err, sizeof err) && u.port == 6379 &&
              !strcmp(u.key, "scenes/hall-1"),
          "default port 6379 and a key with '/': %d %s", u.port, u.key);
    CHECK(parses("redis://:s%40cret%3A@h:1/k", &u, err, sizeof err) && !u.user[0] && !strcmp(u.password, "s@cret:"),
          "password only, percent-decoded: '%s'", u.password);
    CHECK(parses("redis://admin:pw@[::1]:7000/k", &u, err, sizeof err) && !strcmp(u.user, "admin") &&
              !strcmp(u.password, "pw") && !strcmp(u.host, "::1") && u.port == 7000,
          "user, password and an IPv6 host: %s %s %s %d", u.user, u.password, u.host, u.port);
    /* a length, not a NUL: the text after it is not part of the URL */
    const char *longer = "redis://h:1/keyEXTRA";
    CHECK(lc_cluster_parse_url(longer, strlen(longer) - 5, &u, err, sizeof err) == 0 && !strcmp(u.key, "key"),
          "parses only `len` bytes: key '%s'", u.key);
    check_refused("rediss://h:1/k", "TLS");
    check_refused("http://h:1/k", "redis://");
    check_refused("redis://h:1", "no key");
    check_refused("redis://h:1/", "key is missing");
    check_refused("redis://h:0/k", "port");
    check_refused("redis://h:65536/k", "port");
    check_refused("redis://h:/k", "port");
    check_refused("redis://h:12a/k", "port");
    check_refused("redis:///k", "host is missing");
    check_refused("redis://h h/k", "host has a character");
    check_refused("redis://[::1/k", "'[' without ']'");
    check_refused("redis://[::1]x/k", "after the URL's ']'");
    check_refused("redis://user@h/k", "[USER]:PASSWORD@");
    check_refused("redis://:%zz@h/k", "percent-encoded");
    check_refused("redis://:pa/ss@h/k", "password holding '/' must be percent-encoded");
    check_refused("redis://h/a%00b", "key is too long or badly encoded");
    check_refused("redis://h/a b", "key may hold only");
    char big[400];
    snprintf(big, sizeof big, "redis://h/%0*d", LC_CLUSTER_KEY_MAX + 1, 0);
    check_refused(big, "too long");
    CHECK_DONE();
}
