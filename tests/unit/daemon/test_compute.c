/* The compute thread: every submission gets an increasing job id and its result carries it;
 * latest wins; a discarded submission (its journal write failed) is never handed out —
 * whether it was pending, running or already published — while the next one is. Refinement
 * stops once the light still to come is below the tolerance: the converged frame is within
 * 1% of the fully refined one, after fewer passes. */
#include <libwebsockets.h>
#include <math.h>
#include <time.h>

#include "../engine/engine_fixture.h"
#include "check.h"
#include "compute.h"
#include "state.h"

static void test_wake(void *ctx) { lws_cancel_service(ctx); }

/* Waits up to ms for a publication newer than *seen. */
static lc_published *wait_pub(lc_compute *c, uint64_t *seen, int ms) {
    for (int i = 0; i < ms; i += 5) {
        lc_published *p = lc_compute_take_newer(c, seen);
        if (p) return p;
        struct timespec ts = {0, 5 * 1000 * 1000};
        nanosleep(&ts, NULL);
    }
    return NULL;
}

static void no_wake(void *arg) { (void)arg; }

/* Relights the initial state of `bake` with refinement, returns the converged frame (or NULL)
 * and its pass. */
static lc_published *refine_to_convergence(const lc_lcb *bake, double tolerance, int *pass) {
    char err[256];
    lc_compute_refinement r = {.max_passes = 48, .delay_ms = 0, .tolerance = tolerance};
    lc_compute *c = lc_compute_start(bake, LC_BACKEND_CPU, 1, &r, no_wake, NULL, err, sizeof err);
    CHECK(c != NULL, "compute start: %s", err);
    if (!c) return NULL;
    lc_state_limits lim = {.max_lights = 8, .max_objects = 2};
    lc_state s;
    lc_published *out = NULL;
    if (lc_state_init(&s, bake, &lim) != 0) goto done;
    s.settings.bounces = 0; /* lucentd's default: each pass adds one bounce */
    s.revision = 1;
    uint64_t seen = 0;
    CHECK(lc_compute_submit(c, &s, NULL) == 0, "submit");
    lc_published *p;
    while ((p = wait_pub(c, &seen, 5000))) {
        if (p->converged) {
            *pass = p->pass;
            out = lc_published_ref(c, p);
        }
        lc_published_release(c, p);
        if (out) break;
    }
    lc_state_release(&s);
done:
    if (out) { /* the frame outlives the compute thread: copy what the caller reads */
        lc_published *copy = calloc(1, sizeof *copy);
        size_t n = (size_t)out->lm_w * out->lm_h * 3;
        if (copy && (copy->lightmap = malloc(n * sizeof(float)))) {
            memcpy(copy->lightmap, out->lightmap, n * sizeof(float));
            copy->lm_w = out->lm_w;
            copy->lm_h = out->lm_h;
        } else {
            free(copy);
            copy = NULL;
        }
        lc_published_release(c, out);
        out = copy;
    }
    lc_compute_release(c);
    return out;
}

/* A closed 1 m cube, every wall white (0.5) and emitting 1 nit: each bounce adds half the
 * previous one, converging to E = pi Le / (1 - rho) = 2 pi. */
static void test_refinement(void) {
    const char *obj = "usemtl wall\nv 0 0 0\nv 0 0 1\nv 0 1 0\nv 0 1 1\nv 1 0 0\nv 1 0 1\nv 1 1 0\nv 1 1 1\n"
                      "f 1 3 4 2\nf 6 8 7 5\nf 2 6 5 1\nf 3 7 8 4\nf 1 5 7 3\nf 4 8 6 2\n";
    const char *mtl = "newmtl wall\nKd 0.5 0.5 0.5\nKe 1 1 1\n";
    const char *flags[] = {"--quality", "draft", "--surfels", "1024", "--links", "32", "--atlas-size", "32", NULL};
    fixture f;
    if (fixture_bake(&f, obj, mtl, flags) != 0) {
        CHECK(0, "cube bake failed");
        return;
    }
    int pass_tol = -1, pass_all = -1;
    lc_published *tol = refine_to_convergence(f.bake, 1e-3, &pass_tol);
    lc_published *all = refine_to_convergence(f.bake, 0, &pass_all);
    CHECK(tol && all, "both refinements converge");
    if (tol && all) {
        CHECK(pass_all == 48, "tolerance 0 runs every pass (%d)", pass_all);
        CHECK(pass_tol > 3 && pass_tol < 20, "tolerance 1e-3 stops after %d passes (q = 0.5: about 10)", pass_tol);
        double diff = 0, sum = 0, lit = 0, e_sum = 0;
        for (size_t i = 0; i < (size_t)all->lm_w * all->lm_h; i++) {
            double a = all->lightmap[3 * i + 1], t = tol->lightmap[3 * i + 1];
            diff += fabs(t - a);
            sum += a;
            if (a > 0) {
                lit++;
                e_sum += a;
            }
        }
        CHECK(sum > 0 && diff / sum<0.005, "converged frame within 0.5%% of the fully refined one (%.4f%%)", sum> 0
                  ? 100 * diff / sum
                  : -1);
        double e_mean = lit ? e_sum / lit : 0, e_true = 2 * M_PI;
        printf("refinement: tolerance 1e-3 stopped after %d passes, %.3f%% from 48 passes; E %.4f (2 pi = %.4f)\n",
               pass_tol, sum > 0 ? 100 * diff / sum : -1, e_mean, e_true);
        CHECK(fabs(e_mean - e_true) < 0.05 * e_true, "fully refined mean E %.3f vs closed form %.3f", e_mean, e_true);
    }
    if (tol) free(tol->lightmap);
    if (all) free(all->lightmap);
    free(tol);
    free(all);
    fixture_release(&f);
}

int main(void) {
    test_refinement();
    const char *obj = "usemtl white\nv 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nf 1 4 3 2\n"
                      "usemtl lamp\nv 0 1 0\nv 1 1 0\nv 1 1 1\nv 0 1 1\nf 5 6 7 8\n";
    const char *mtl = "newmtl white\nKd 0.5 0.5 0.5\nnewmtl lamp\nKd 0 0 0\nKe 2 2 2\n";
    const char *flags[] = {"--quality", "draft", "--surfels", "256", "--links", "16", NULL};
    fixture f;
    if (fixture_bake(&f, obj, mtl, flags) != 0) {
        CHECK(0, "bake failed");
        CHECK_DONE();
    }
    struct lws_context_creation_info info;
    memset(&info, 0, sizeof info);
    info.port = CONTEXT_PORT_NO_LISTEN;
    lws_set_log_level(0, NULL);
    struct lws_context *ctx = lws_create_context(&info);
    CHECK(ctx != NULL, "lws context");
    char err[256];
    lc_compute_refinement none = {0, 0, 0, 0};
    lc_compute *c = lc_compute_start(f.bake, LC_BACKEND_CPU, 1, &none, test_wake, ctx, err, sizeof err);
    CHECK(c != NULL, "compute start: %s", err);
    if (!c || !ctx) CHECK_DONE();
    lc_state_limits lim = {.max_lights = 8, .max_objects = 2};
    lc_state s;
    CHECK(lc_state_init(&s, f.bake, &lim) == 0, "state");

    uint64_t seen = 0, job1 = 0, job2 = 0, job3 = 0;
    CHECK(lc_compute_submit(c, &s, &job1) == 0 && job1 == 1, "first job id %llu", (unsigned long long)job1);
    lc_published *p = wait_pub(c, &seen, 5000);
    CHECK(p && p->job == job1 && p->revision == s.revision, "published job 1");
    lc_published_release(c, p);

    /* a discarded submission never shows up, whether it was pending or already running */
    for (int round = 0; round < 20; round++) {
        s.revision++;
        CHECK(lc_compute_submit(c, &s, &job2) == 0 && job2 > job1, "job id grows");
        lc_compute_discard(c, job2);
        s.revision--;
        CHECK(lc_compute_submit(c, &s, &job3) == 0 && job3 == job2 + 1, "resubmit");
        lc_published *q;
        int got3 = 0;
        while ((q = wait_pub(c, &seen, got3 ? 100 : 5000))) {
            CHECK(q->job != job2, "discarded job %llu was published", (unsigned long long)job2);
            if (q->job == job3) got3 = 1;
            lc_published_release(c, q);
        }
        CHECK(got3, "the resubmission was published (round %d)", round);
        job1 = job3;
    }
    /* withdrawn when it was already published but not yet taken (a relight faster than the
     * journal write) */
    uint64_t before = lc_compute_count(c);
    s.revision++;
    CHECK(lc_compute_submit(c, &s, &job2) == 0, "submit");
    for (int i = 0; i < 1000 && lc_compute_count(c) == before; i++) {
        struct timespec ts = {0, 2 * 1000 * 1000};
        nanosleep(&ts, NULL);
    }
    CHECK(lc_compute_count(c) > before, "published");
    lc_compute_discard(c, job2);
    lc_published *w = lc_compute_take_newer(c, &seen);
    CHECK(w == NULL || w->job != job2, "a withdrawn result was handed out");
    lc_published_release(c, w);
    s.revision--;
    CHECK(lc_compute_submit(c, &s, &job3) == 0, "resubmit after withdrawal");
    w = wait_pub(c, &seen, 5000);
    CHECK(w && w->job == job3, "the resubmission is published after a withdrawal");
    lc_published_release(c, w);
    /* A relight that fails (a state the engine refuses, slipped past the checks) is
     * recorded for the service thread to report, and cleared by the next good relight. */
    {
        CHECK(lc_compute_failure(c, NULL, NULL, 0) == 0, "no failure recorded after good relights");
        lc_proto_light bad;
        memset(&bad, 0, sizeof bad);
        snprintf(bad.id, sizeof bad.id, "nan");
        bad.type = LC_PLIGHT_POINT;
        bad.color[0] = bad.color[1] = bad.color[2] = 1;
        bad.intensity = NAN;
        lc_state broken;
        CHECK(lc_state_clone(&broken, &s) == 0, "clone");
        lc_proto_light *nl = realloc(broken.lights, sizeof *nl);
        if (nl) {
            broken.lights = nl;
            broken.lights[0] = bad;
            broken.n_lights = 1;
        }
        broken.revision = 777;
        uint64_t failures = 0;
        char why[256] = "";
        CHECK(lc_compute_submit(c, &broken, NULL) == 0, "submit a state the engine refuses");
        for (int i = 0; i < 1000 && lc_compute_failure(c, &failures, why, sizeof why) == 0; i++) {
            struct timespec ts = {0, 2 * 1000 * 1000};
            nanosleep(&ts, NULL);
        }
        CHECK(lc_compute_failure(c, &failures, why, sizeof why) == 777 && failures == 1 && strstr(why, "intensity"),
              "the failed relight is recorded with its revision and cause (%llu: %s)", (unsigned long long)failures,
              why);
        lc_state_release(&broken);
        s.revision++;
        CHECK(lc_compute_submit(c, &s, NULL) == 0, "submit a good state");
        lc_published *g = wait_pub(c, &seen, 5000);
        CHECK(g != NULL && lc_compute_failure(c, &failures, NULL, 0) == 0 && failures == 1,
              "a good relight clears the failure, the count stays");
        lc_published_release(c, g);
    }
    lc_compute_release(c);
    lc_state_release(&s);
    lws_context_destroy(ctx);
    fixture_release(&f);
    CHECK_DONE();
}
