/* lucent-ref capture and mr-truth (tools/ref/capture.c, mr_truth.c) against closed forms:
 *  - the camera model (PROTOCOL.md 8.4): the look-at view's intrinsics are (H/2)/tan(fov/2),
 *    W/2, H/2 and its rays are lc_ref_camera_ray's; the written depth of every pixel decodes to
 *    the centre ray's z within 0.5 mm, and unprojecting it with the written intrinsics and pose
 *    lands on the surface the ray hit (and on a wall of the box, checked without the ray code);
 *  - colour: an emissive closed box of albedo 0 shows L_e at every pixel; of albedo rho,
 *    L_e / (1 - rho) (all bounces), identical on 1 and 2 threads; on the Cornell bake (with
 *    its lights) it is the camera view (lc_ref_camera_render) per pixel within the noise;
 *  - PATH.json and --frames/--jitter poses: times, bounds, errors naming the JSON pointer;
 *  - mr-truth visible: a synthetic capture of one uniformly radiant rectangle in front of the
 *    camera gives pi L F(point -> rectangle); nothing from behind it; no triangle across a depth
 *    step; full: pi L_e at the centre of an emissive closed box, pi L_e (1 - F) with a cube
 *    occluder above the point (both estimators mix light and cosine samples: within 3 stderr). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "engine/engine_fixture.h"
#include "ref/ref.h"

/* Form factor from a differential area to a parallel rectangle [0,x]x[0,z] at height c, one
 * corner above the point (as test_ref.c). */
static double ff_corner(double x, double z, double c) {
    double X = fabs(x) / c, Z = fabs(z) / c;
    double f = (X / sqrt(1 + X * X) * atan(Z / sqrt(1 + X * X)) + Z / sqrt(1 + Z * Z) * atan(X / sqrt(1 + Z * Z))) /
        (2 * M_PI);
    return (x < 0 ? -1 : 1) * (z < 0 ? -1 : 1) * f;
}
static double ff_rect(double px, double pz, double x0, double x1, double z0, double z1, double c) {
    x0 -= px, x1 -= px, z0 -= pz, z1 -= pz;
    return ff_corner(x1, z1, c) - ff_corner(x0, z1, c) - ff_corner(x1, z0, c) + ff_corner(x0, z0, c);
}

static const char *box_flags[] = {"--surfels",
                                  "1024",
                                  "--links",
                                  "16",
                                  "--node-samples",
                                  "4",
                                  "--final-samples",
                                  "4",
                                  "--probe-rays",
                                  "64",
                                  "--atlas-size",
                                  "32",
                                  "--grid-max-dim",
                                  "4",
                                  NULL};

/* The unit box [0,1]^3 wound inward, all walls albedo rho, L_e = 1. */
static int bake_box(fixture *f, double rho, const char **flags) {
    static char obj[1 << 16];
    char mtl[128];
    obj[0] = 0;
    fixture_inward_box(obj, sizeof obj, 1.0f, 4, "wall", 1);
    snprintf(mtl, sizeof mtl, "newmtl wall\nKd %g %g %g\nKe 1 1 1\n", rho, rho, rho);
    return fixture_bake(f, obj, mtl, flags ? flags : box_flags);
}

static lc_ref *make_ref(const fixture *f, int threads) {
    static lc_engine_state st;
    char err[256];
    memset(&st, 0, sizeof st);
    st.settings = lc_engine_default_settings(f->bake);
    lc_ref *r = lc_ref_create(f->bake, &st, threads, err, sizeof err);
    if (!r) fprintf(stderr, "lc_ref_create: %s\n", err);
    return r;
}

static void rm_capture(const char *dir, uint32_t frames) {
    char p[256];
    const char *kinds[] = {"frame_%05u.json", "depth_%05u.png", "color_%05u.png"};
    for (uint32_t k = 1; k <= frames; k++)
        for (int i = 0; i < 3; i++) {
            char name[64];
            snprintf(name, sizeof name, kinds[i], k);
            snprintf(p, sizeof p, "%s/%s", dir, name);
            unlink(p);
        }
    snprintf(p, sizeof p, "%s/capture.json", dir);
    unlink(p);
    rmdir(dir);
}

/* The camera model: intrinsics and rays of the look-at view against lc_ref_camera_ray. */
static void test_camera_model(void) {
    lc_ref_camera cam = {{0.3f, 0.6f, 0.8f}, {0.6f, 0.4f, 0.1f}, {0, 1, 0}, 70.0, 48, 36};
    lc_ref_rgbd_view view;
    lc_ref_camera_basis b;
    char err[256];
    CHECK(lc_ref_rgbd_lookat(&cam, &view, err, sizeof err) == 0, "lookat: %s", err);
    CHECK(lc_ref_camera_setup(&cam, &b, err, sizeof err) == 0, "setup: %s", err);
    CHECK_NEAR(view.fx, 18.0 / tan(35.0 * M_PI / 180.0), 1e-12);
    CHECK_NEAR(view.fy, view.fx, 1e-12);
    CHECK_NEAR(view.cx, 24.0, 1e-12);
    CHECK_NEAR(view.cy, 18.0, 1e-12);
    double worst = 0, m[9], q[4];
    for (uint32_t y = 0; y < 36; y++)
        for (uint32_t x = 0; x < 48; x++) {
            float org[3], d1[3], d2[3];
            lc_ref_rgbd_ray(&view, x + 0.5, y + 0.5, org, d1, NULL);
            lc_ref_camera_ray(&b, 48, 36, x + 0.5, y + 0.5, d2);
            for (int k = 0; k < 3; k++) worst = fmax(worst, fabs(d1[k] - d2[k]));
        }
    CHECK(worst < 2e-6, "rgbd rays differ from lc_ref_camera_ray by %g", worst);
    /* -Z of the camera is the view direction, +Y its up; the quaternion round-trips. */
    lc_ref_quat_matrix(view.rotation, m);
    for (int k = 0; k < 3; k++) {
        CHECK_NEAR(-m[3 * k + 2], b.forward[k], 1e-9);
        CHECK_NEAR(m[3 * k + 1], b.up[k], 1e-9);
    }
    lc_ref_matrix_quat(m, q);
    for (int k = 0; k < 4; k++) CHECK_NEAR(q[k], view.rotation[k], 1e-9);
    CHECK(lc_ref_rgbd_lookat(&(lc_ref_camera){{0, 0, 0}, {0, 0, 0}, {0, 1, 0}, 60, 8, 8}, &view, err, sizeof err) !=
                  0 &&
              strstr(err, "--target"),
          "eye = target accepted (%s)", err);
}

/* Every pixel of a read-back frame: depth = the centre ray's z within 0.5 mm; the unprojected
 * point is the ray's hit and lies on a wall of the unit box. Colour = want (if > 0). */
static void check_frame(const lc_ref *r, const lc_ref_capture_frame *fr, double want) {
    const lc_ref_rgbd_view *v = &fr->view;
    double worst_z = 0, worst_p = 0, worst_wall = 0, worst_c = 0;
    uint32_t zero = 0;
    for (uint32_t y = 0; y < v->height; y++)
        for (uint32_t x = 0; x < v->width; x++) {
            size_t i = (size_t)y * v->width + x;
            float org[3], dir[3], ng[3], t;
            double zt, p[3];
            lc_ref_rgbd_ray(v, x + 0.5, y + 0.5, org, dir, &zt);
            if (!lc_ref_first_hit(r, org, dir, &t, ng) || !fr->depth_mm[i]) {
                zero++;
                continue;
            }
            double z = fr->depth_mm[i] / 1000.0;
            worst_z = fmax(worst_z, fabs(z - t * zt));
            lc_ref_rgbd_unproject(v, x + 0.5, y + 0.5, z, p);
            double d2 = 0, wall = 1;
            for (int k = 0; k < 3; k++) {
                double h = org[k] + (double)t * dir[k];
                d2 += (p[k] - h) * (p[k] - h);
                wall = fmin(wall, fmin(fabs(p[k]), fabs(p[k] - 1)));
            }
            /* 0.5 mm of depth is 0.5 mm / zt along the ray. */
            worst_p = fmax(worst_p, sqrt(d2) * zt);
            worst_wall = fmax(worst_wall, wall * zt);
            for (int k = 0; k < 3 && want > 0; k++) worst_c = fmax(worst_c, fabs(fr->rgb[3 * i + k] - want));
        }
    CHECK(zero == 0, "%u pixels without depth in a closed box", zero);
    CHECK(worst_z <= 0.0005 + 1e-6, "depth off the ray's z by %.3g m", worst_z);
    CHECK(worst_p <= 0.0005 + 2e-6, "unprojected point off the hit by %.3g m (x z per t)", worst_p);
    CHECK(worst_wall <= 0.0005 + 2e-6, "unprojected point off the walls by %.3g m (x z per t)", worst_wall);
    CHECK(want <= 0 || worst_c <= want / 65535.0 + 1e-6, "colour off L_e = %g by %.3g", want, worst_c);
}

/* An emissive closed box of albedo 0 recorded by lc_ref_capture_run and read back. */
static void test_capture_box(void) {
    fixture f;
    if (bake_box(&f, 0.0, NULL) != 0) {
        CHECK(0, "box bake failed");
        return;
    }
    lc_ref *r = make_ref(&f, 0);
    lc_ref_camera cam = {{0.3f, 0.6f, 0.8f}, {0.6f, 0.4f, 0.1f}, {0, 1, 0}, 70.0, 48, 36};
    lc_ref_rgbd_view base;
    lc_ref_capture_pose poses[3];
    char err[512], dir[64] = "/tmp/lc_capture_XXXXXX";
    CHECK(r && mkdtemp(dir) && lc_ref_rgbd_lookat(&cam, &base, err, sizeof err) == 0, "setup");
    lc_ref_capture_jitter(&base, 3, 20.0, 3.0, 7, poses);
    lc_ref_capture_settings s = {4, 32, 3, 1, 0, 1};
    if (r && lc_ref_capture_run(r, dir, poses, 3, &s, f.lcb_path, NULL, err, sizeof err) != 0)
        CHECK(0, "capture: %s", err);
    for (uint32_t k = 1; r && k <= 3; k++) {
        lc_ref_capture_frame fr;
        if (lc_ref_capture_read_frame(dir, k, &fr, err, sizeof err) != 0) {
            CHECK(0, "read frame %u: %s", k, err);
            continue;
        }
        CHECK(fr.sequence == k && fr.time_us == (uint64_t)(k - 1) * 100000u, "frame %u: sequence %u time %llu", k,
              fr.sequence, (unsigned long long)fr.time_us);
        CHECK_NEAR(fr.exposure, 1.0, 1e-6);
        CHECK(!fr.srgb8, "frame %u: colour is not linear16", k);
        for (int q = 0; q < 3; q++) CHECK_NEAR(fr.view.translation[q], poses[k - 1].view.translation[q], 1e-12);
        for (int q = 0; q < 4; q++) CHECK_NEAR(fr.view.rotation[q], poses[k - 1].view.rotation[q], 1e-12);
        CHECK_NEAR(fr.view.fx, base.fx, 1e-12);
        check_frame(r, &fr, 1.0);
        lc_ref_capture_frame_free(&fr);
    }
    lc_ref_capture_frame fr;
    CHECK(lc_ref_capture_read_frame(dir, 4, &fr, err, sizeof err) != 0 && strstr(err, "--frame"),
          "frame 4 of 3 read (%s)", err);
    rm_capture(dir, 3);
    lc_ref_release(r);
    fixture_release(&f);
}

/* Albedo 0.5, L_e 1: every pixel sees L = 2 (all bounces); same image on 1 and 2 threads. */
static void test_capture_bounces(void) {
    fixture f;
    if (bake_box(&f, 0.5, NULL) != 0) {
        CHECK(0, "box bake failed");
        return;
    }
    lc_ref *r1 = make_ref(&f, 1), *r2 = make_ref(&f, 2);
    lc_ref_camera cam = {{0.5f, 0.5f, 0.9f}, {0.5f, 0.5f, 0.0f}, {0, 1, 0}, 60.0, 32, 24};
    lc_ref_rgbd_view view;
    char err[256];
    enum { N = 32 * 24 };
    static float rgb1[3 * N], rgb2[3 * N], d1[N], d2[N];
    lc_ref_capture_settings s = {16, 32, 3, 5, 0, 1};
    int ok = r1 && r2 && lc_ref_rgbd_lookat(&cam, &view, err, sizeof err) == 0 &&
        lc_ref_rgbd_render(r1, &view, &s, 0, rgb1, d1, NULL, err, sizeof err) == 0 &&
        lc_ref_rgbd_render(r2, &view, &s, 0, rgb2, d2, NULL, err, sizeof err) == 0;
    CHECK(ok, "render: %s", err);
    if (ok) {
        double sum = 0, sq = 0;
        for (int i = 0; i < N; i++) sum += rgb1[3 * i], sq += (double)rgb1[3 * i] * rgb1[3 * i];
        double mean = sum / N, sd = sqrt(fmax(sq / N - mean * mean, 0)), se = sd / sqrt((double)N);
        CHECK(fabs(mean - 2.0) <= 3 * se + 1e-3, "mean pixel %.5f, expected 2 (stderr %.5f)", mean, se);
        fprintf(stderr, "albedo 0.5 box: mean pixel %.5f (expected 2), stderr %.5f\n", mean, se);
        CHECK(memcmp(rgb1, rgb2, sizeof rgb1) == 0 && memcmp(d1, d2, sizeof d1) == 0, "1 and 2 threads differ");
        /* The centre pixel looks straight at the back wall z = 0 from z = 0.9. */
        CHECK(fabs(d1[12 * 32 + 16] - 0.9 / 1.0) < 0.02, "centre depth %.4f", d1[12 * 32 + 16]);
    }
    lc_ref_release(r1);
    lc_ref_release(r2);
    fixture_release(&f);
}

/* The capture's colour is the camera view (lc_ref_camera_render) of the embedded Cornell bake,
 * with the bake's lights as `lucent-ref camera` and `capture` load them: per pixel within the
 * two estimates' noise, independent random streams. Skipped without build/cornell.lcb. */
static void test_capture_vs_camera(void) {
    const char *bin = getenv("LUCENT_BINARY_DIR");
    char path[512], err[512];
    snprintf(path, sizeof path, "%s/cornell.lcb", bin ? bin : ".");
    lc_lcb *bake = NULL;
    if (access(path, R_OK) != 0 || lc_lcb_open(path, &bake, err, sizeof err) != 0) {
        fprintf(stderr, "capture vs camera: skipped (%s not readable)\n", path);
        return;
    }
    lc_ref_state st;
    lc_ref *r = NULL;
    if (lc_ref_state_load(bake, NULL, 1, &st, err, sizeof err) != 0 ||
        !(r = lc_ref_create(bake, &st.st, 0, err, sizeof err))) {
        CHECK(0, "cornell: %s", err);
        lc_lcb_close(bake);
        return;
    }
    enum { W = 40, H = 30, N = W * H };
    lc_ref_camera cam = {{0.278f, 0.273f, -0.8f}, {0.278f, 0.273f, 0.0f}, {0, 1, 0}, 60.0, W, H};
    lc_ref_camera_settings cs = {64, 32, 3, 1, 1};
    lc_ref_capture_settings s = {64, 32, 3, 2, 0, 1};
    lc_ref_rgbd_view view;
    lc_ref_image img;
    memset(&img, 0, sizeof img);
    static float rgb[3 * N], depth[N];
    if (lc_ref_rgbd_lookat(&cam, &view, err, sizeof err) != 0 ||
        lc_ref_camera_render(r, &cam, &cs, &img, err, sizeof err) != 0 ||
        lc_ref_rgbd_render(r, &view, &s, 0, rgb, depth, NULL, err, sizeof err) != 0) {
        CHECK(0, "cornell renders: %s", err);
    } else {
        double sum_d = 0, sum_var = 0, sum_y = 0;
        int beyond = 0, empty = 0;
        for (int i = 0; i < N; i++) {
            double yc = 0.2126 * rgb[3 * i] + 0.7152 * rgb[3 * i + 1] + 0.0722 * rgb[3 * i + 2];
            double yr = 0.2126 * img.rgb[3 * i] + 0.7152 * img.rgb[3 * i + 1] + 0.0722 * img.rgb[3 * i + 2];
            double se = sqrt(2.0) * img.stderr_y[i]; /* the same estimator at the same spp, twice */
            sum_d += yc - yr, sum_var += se * se, sum_y += yr;
            if (fabs(yc - yr) > 5 * se + 1e-6) beyond++; /* silhouette pixels: partly covered, few hits */
            if (!depth[i]) empty += yc == 0;
        }
        CHECK(fabs(sum_d) <= 3 * sqrt(sum_var) + 1e-4 * sum_y,
              "capture - camera luminance %.5f over %d pixels (3 sigma %.5f)", sum_d, N, 3 * sqrt(sum_var));
        CHECK(beyond <= N / 100, "%d of %d pixels differ by more than 5 sigma", beyond, N);
        CHECK(empty > 0, "no pixel without a surface (and colour) around the open box");
        fprintf(stderr, "capture vs camera (Cornell %dx%d, 64 spp): mean luminance %.5f vs %.5f, %d pixels > 5 sigma\n",
                W, H, (sum_y + sum_d) / N, sum_y / N, beyond);
    }
    lc_ref_image_free(&img);
    lc_ref_release(r);
    lc_ref_state_free(&st);
    lc_lcb_close(bake);
}

static int write_text(const char *path, const char *text) {
    FILE *fp = fopen(path, "w");
    if (!fp) return -1;
    fputs(text, fp);
    return fclose(fp);
}

/* PATH.json poses and their errors; the jitter's bounds and seed. */
static void test_poses(void) {
    char dir[64] = "/tmp/lc_path_XXXXXX", path[128], err[512];
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    snprintf(path, sizeof path, "%s/path.json", dir);
    lc_ref_camera tmpl = {{0, 0, 0}, {0, 0, -1}, {0, 1, 0}, 60.0, 16, 12};
    lc_ref_capture_pose *poses = NULL;
    uint32_t n = 0;
    write_text(path,
               "{\"frames\": [{\"eye\": [0, 1, 2], \"target\": [0, 1, 0]},"
               " {\"eye\": [1, 0, 0], \"target\": [0, 0, 0], \"up\": [0, 0, 1], \"time_us\": 12345}]}");
    CHECK(lc_ref_capture_path_load(path, &tmpl, &poses, &n, err, sizeof err) == 0 && n == 2, "path: %s", err);
    if (poses && n == 2) {
        CHECK(poses[0].time_us == 0 && poses[1].time_us == 12345, "times %llu %llu",
              (unsigned long long)poses[0].time_us, (unsigned long long)poses[1].time_us);
        CHECK_NEAR(poses[0].view.translation[2], 2.0, 1e-12);
        double m[9];
        lc_ref_quat_matrix(poses[1].view.rotation, m); /* looks along -X, up +Z */
        CHECK_NEAR(-m[2], -1.0, 1e-9);
        CHECK_NEAR(m[7], 1.0, 1e-9);
        CHECK(poses[1].view.width == 16 && poses[1].view.height == 12, "size from the template");
    }
    free(poses);
    const char *bad[][2] = {
        {"{\"frames\": []}", "/frames"},
        {"{\"frames\": [{\"eye\": [0, 0], \"target\": [1, 0, 0]}]}", "/frames/0/eye"},
        {"{\"frames\": [{\"eye\": [0,0,0], \"target\": [1,0,0]}, {\"eye\": [0,0,0]}]}", "/frames/1/target"},
        {"{\"frames\": [{\"eye\": [0,0,0], \"target\": [1,0,0], \"time_us\": -1}]}", "/frames/0/time_us"},
        {"{\"frames\": [{\"eye\": [0,0,0], \"target\": [0,0,0]}]}", "/frames/0"}};
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        write_text(path, bad[i][0]);
        err[0] = 0;
        poses = NULL;
        int rc = lc_ref_capture_path_load(path, &tmpl, &poses, &n, err, sizeof err);
        CHECK(rc != 0 && strstr(err, bad[i][1]) && strstr(err, path), "bad path %zu accepted or error '%s'", i, err);
        free(poses);
    }
    unlink(path);
    rmdir(dir);
    lc_ref_rgbd_view base;
    CHECK(lc_ref_rgbd_lookat(&tmpl, &base, err, sizeof err) == 0, "lookat");
    enum { J = 200 };
    static lc_ref_capture_pose a[J], b[J];
    lc_ref_capture_jitter(&base, J, 10.0, 5.0, 3, a);
    lc_ref_capture_jitter(&base, J, 10.0, 5.0, 3, b);
    CHECK(memcmp(a, b, sizeof a) == 0, "jitter not deterministic for a seed");
    double max_t = 0, max_deg = 0;
    for (int k = 0; k < J; k++) {
        for (int q = 0; q < 3; q++) max_t = fmax(max_t, fabs(a[k].view.translation[q] - base.translation[q]));
        double dot = 0;
        for (int q = 0; q < 4; q++) dot += a[k].view.rotation[q] * base.rotation[q];
        max_deg = fmax(max_deg, 2 * acos(fmin(1.0, fabs(dot))) * 180 / M_PI);
        CHECK(a[k].time_us == (uint64_t)k * 100000u, "jitter time %d", k);
    }
    CHECK(max_t <= 0.010 + 1e-12 && max_t > 0.009, "translation jitter max %.5f m (want <= 10 mm, near it)", max_t);
    CHECK(max_deg <= 5.0 + 1e-6 && max_deg > 4.5, "rotation jitter max %.3f deg (want <= 5, near it)", max_deg);
    lc_ref_capture_jitter(&base, 2, 0, 0, 3, a);
    for (int q = 0; q < 3; q++) CHECK(a[1].view.translation[q] == base.translation[q], "no jitter moved the camera");
    for (int q = 0; q < 4; q++) CHECK_NEAR(a[1].view.rotation[q], base.rotation[q], 1e-12);
}

static void test_png(void) {
    char dir[64] = "/tmp/lc_png_XXXXXX", path[128], err[256];
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    snprintf(path, sizeof path, "%s/a.png", dir);
    static uint16_t in[5 * 3 * 3];
    for (int i = 0; i < 45; i++) in[i] = (uint16_t)(i * 1489 + 7);
    for (int bits = 8; bits <= 16; bits += 8)
        for (int ch = 1; ch <= 3; ch += 2) {
            uint16_t *out = NULL, want[45];
            uint32_t w = 0, h = 0;
            int c = 0, b = 0;
            for (int i = 0; i < 45; i++) want[i] = bits == 8 ? in[i] % 256 : in[i];
            CHECK(lc_ref_png_write(path, 5, 3, ch, bits, want, err, sizeof err) == 0, "write: %s", err);
            CHECK(lc_ref_png_read(path, 64, &w, &h, &c, &b, &out, err, sizeof err) == 0, "read: %s", err);
            CHECK(out && w == 5 && h == 3 && c == ch && b == bits && !memcmp(out, want, 15 * ch * sizeof *out),
                  "%d-bit %d-channel PNG does not round-trip", bits, ch);
            free(out);
        }
    uint16_t *out = NULL;
    uint32_t w, h;
    int c, b;
    CHECK(lc_ref_png_read(path, 4, &w, &h, &c, &b, &out, err, sizeof err) != 0 && strstr(err, path),
          "5x3 PNG read with max side 4 (%s)", err);
    unlink(path);
    rmdir(dir);
    CHECK_NEAR(lc_ref_srgb_eotf(0.0), 0.0, 1e-12);
    CHECK_NEAR(lc_ref_srgb_eotf(1.0), 1.0, 1e-12);
    CHECK_NEAR(lc_ref_srgb_eotf(0.5), pow((0.5 + 0.055) / 1.055, 2.4), 1e-12);
    CHECK_NEAR(lc_ref_srgb_eotf(0.04), 0.04 / 12.92, 1e-12);
}

/* A synthetic frame: identity pose, 64x48, fx = fy = 40; depth 1 m (columns from split on: 1.5 m)
 * and radiance L over pixels x in [10, 50), y in [8, 40), nothing elsewhere. */
static int write_wall_frame(const char *dir, uint32_t k, uint32_t split, const float L[3]) {
    enum { W = 64, H = 48 };
    static float rgb[W * H * 3], depth[W * H];
    lc_ref_capture_pose pose;
    memset(&pose, 0, sizeof pose);
    pose.view = (lc_ref_rgbd_view){W, H, 40, 40, 32, 24, {0, 0, 0, 1}, {0, 0, 0}};
    pose.time_us = (k - 1) * 100000u;
    for (uint32_t y = 0; y < H; y++)
        for (uint32_t x = 0; x < W; x++) {
            size_t i = (size_t)y * W + x;
            int in = x >= 10 && x < 50 && y >= 8 && y < 40;
            depth[i] = in ? (x >= split ? 1.5f : 1.0f) : 0.0f;
            for (int q = 0; q < 3; q++) rgb[3 * i + q] = in ? L[q] : 0.0f;
        }
    char err[256];
    if (lc_ref_capture_write_frame(dir, k, &pose, rgb, depth, 0, NULL, err, sizeof err) != 0) {
        fprintf(stderr, "write frame: %s\n", err);
        return -1;
    }
    return 0;
}

/* visible: pi L F(point -> the rectangle of pixel centres), 0 from behind, no triangle across a
 * depth step. The bake (a box around [0,1]^3) only feeds `full`, not checked here. */
static void test_mr_visible(lc_ref *r, const lc_lcb_view *v) {
    char dir[64] = "/tmp/lc_mrvis_XXXXXX", path[128], err[512];
    const float L[3] = {2.0f, 1.0f, 0.5f};
    CHECK(mkdtemp(dir) != NULL, "mkdtemp");
    snprintf(path, sizeof path, "%s/capture.json", dir);
    write_text(path, "{\"format\": \"lucent-rgbd/1\", \"width\": 64, \"height\": 48, \"frames\": 2, \"source\": {}}");
    if (write_wall_frame(dir, 1, 1000, L) != 0 || write_wall_frame(dir, 2, 30, L) != 0) CHECK(0, "frames");
    lc_ref_mr_point pts[2] = {{{0.1f, -0.05f, -0.2f}, {0, 0, -1}}, {{0.0f, 0.0f, -1.5f}, {0, 0, 1}}};
    lc_ref_mr_input in = {pts, 2, NULL, 0};
    lc_ref_mr_settings s = {40000, 32, 3, 11, 1};
    lc_ref_mr_value out[2];
    uint32_t tris = 0;
    lc_ref_capture_frame fr;
    if (lc_ref_capture_read_frame(dir, 1, &fr, err, sizeof err) != 0) CHECK(0, "read: %s", err);
    else if (lc_ref_mr_truth(r, v, &fr, &in, &s, out, &tris, err, sizeof err) != 0) CHECK(0, "mr: %s", err);
    else {
        double F = ff_rect(0.1, -0.05, (10.5 - 32) / 40, (49.5 - 32) / 40, -(39.5 - 24) / 40, -(8.5 - 24) / 40, 0.8);
        for (int q = 0; q < 3; q++) {
            double want = M_PI * L[q] * F, got = out[0].visible[q], se = out[0].visible_stderr[q];
            CHECK(fabs(got - want) <= 3 * se + 2e-4 * want && se > 0 && se < 0.02 * want,
                  "visible[%d] %.5f, pi L F = %.5f (stderr %.5f)", q, got, want, se);
            CHECK(out[1].visible[q] == 0, "visible from behind the wall: %g", out[1].visible[q]);
        }
        fprintf(stderr, "mr visible: %.5f vs pi L F %.5f (F %.5f), stderr %.5f\n", out[0].visible[0], M_PI * L[0] * F,
                F, out[0].visible_stderr[0]);
        CHECK(tris == 2 * 39 * 31, "%u triangles, want %d", tris, 2 * 39 * 31);
    }
    lc_ref_capture_frame_free(&fr);
    s.spp = 1;
    if (lc_ref_capture_read_frame(dir, 2, &fr, err, sizeof err) != 0) CHECK(0, "read: %s", err);
    else if (lc_ref_mr_truth(r, v, &fr, &in, &s, out, &tris, err, sizeof err) != 0) CHECK(0, "mr: %s", err);
    else CHECK(tris == 2 * 38 * 31, "%u triangles across a 1 m / 1.5 m step, want %d", tris, 2 * 38 * 31);
    lc_ref_capture_frame_free(&fr);
    rm_capture(dir, 2);
}

/* A cube asset [-0.5, 0.5]^3 (outward) as OBJ in dir; path into out. */
static int write_cube(const char *dir, char *out, size_t cap) {
    char p[160];
    snprintf(p, sizeof p, "%s/cube.mtl", dir);
    if (write_text(p, "newmtl c\nKd 0.5 0.5 0.5\n") != 0) return -1;
    snprintf(out, cap, "cube=%s/cube.obj", dir);
    snprintf(p, sizeof p, "%s/cube.obj", dir);
    return write_text(p,
                      "mtllib cube.mtl\nusemtl c\n"
                      "v -0.5 -0.5 -0.5\nv 0.5 -0.5 -0.5\nv 0.5 0.5 -0.5\nv -0.5 0.5 -0.5\n"
                      "v -0.5 -0.5 0.5\nv 0.5 -0.5 0.5\nv 0.5 0.5 0.5\nv -0.5 0.5 0.5\n"
                      "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 4 8 7 3\nf 1 5 8 4\nf 2 3 7 6\n");
}

/* full at the centre of the emissive box: pi L_e; with the cube (side 0.2, 0.15 m above)
 * blocking: pi L_e (1 - F(point -> its bottom face)). POINTS.json's errors name the field. */
static void test_mr_full(void) {
    char dir[64] = "/tmp/lc_mrfull_XXXXXX", asset[200], path[128], err[512];
    CHECK(mkdtemp(dir) && write_cube(dir, asset, sizeof asset) == 0, "cube asset");
    const char *flags[32];
    int nf = 0;
    for (; box_flags[nf]; nf++) flags[nf] = box_flags[nf];
    flags[nf++] = "--asset";
    flags[nf++] = asset;
    flags[nf] = NULL;
    fixture f;
    if (bake_box(&f, 0.0, flags) != 0) {
        CHECK(0, "box + cube bake failed");
        return;
    }
    lc_ref *r = make_ref(&f, 0);
    snprintf(path, sizeof path, "%s/points.json", dir);
    write_text(path,
               "{\"points\": [{\"position\": [0.5, 0.5, 0.5], \"normal\": [0.3, 0.8, -0.5]},"
               " {\"position\": [0.5, 0.5, 0.5], \"normal\": [0, 2, 0]}],"
               " \"occluders\": {\"objects\": [{\"asset\": \"cube\", \"translation\": [0.5, 0.75, 0.5],"
               " \"scale\": 0.2}]}}");
    lc_ref_mr_input in;
    lc_ref_mr_settings s = {20000, 32, 3, 3, 1};
    lc_ref_mr_value out[2];
    if (!r || lc_ref_mr_points_load(path, f.v, &in, err, sizeof err) != 0) CHECK(0, "points: %s", err);
    else {
        CHECK(in.n_points == 2 && in.n_occluders == 1 && fabsf(in.points[1].normal[1] - 1) < 1e-6f, "loaded");
        lc_ref_mr_input none = {in.points, in.n_points, NULL, 0};
        if (lc_ref_mr_truth(r, f.v, NULL, &none, &s, out, NULL, err, sizeof err) != 0) CHECK(0, "mr: %s", err);
        for (int i = 0; i < 2; i++)
            CHECK(fabs(out[i].full[0] - M_PI) <= 3 * out[i].full_stderr[0] + 1e-4 && out[i].full_stderr[0] < 0.01 &&
                      out[i].visible[0] == 0,
                  "full %d without occluders %.6f (stderr %.3g), want pi", i, out[i].full[0], out[i].full_stderr[0]);
        if (lc_ref_mr_truth(r, f.v, NULL, &in, &s, out, NULL, err, sizeof err) != 0) CHECK(0, "mr: %s", err);
        double want = M_PI * (1 - ff_rect(0, 0, -0.1, 0.1, -0.1, 0.1, 0.15));
        CHECK(fabs(out[1].full[1] - want) <= 3 * out[1].full_stderr[1] + 1e-4 && out[1].full[1] < M_PI - 0.1,
              "full under the cube %.5f, want %.5f (stderr %.5f)", out[1].full[1], want, out[1].full_stderr[1]);
        fprintf(stderr, "mr full under a cube: %.5f vs %.5f, stderr %.5f\n", out[1].full[1], want,
                out[1].full_stderr[1]);
        lc_ref_mr_input_free(&in);
    }
    const char *bad[][2] = {
        {"{\"points\": []}", "/points"},
        {"{\"points\": [{\"position\": [0, 0, 0], \"normal\": [0, 0, 0]}]}", "/points/0/normal"},
        {"{\"points\": [{\"position\": [0, 0], \"normal\": [0, 1, 0]}]}", "/points/0/position"},
        {"{\"points\": [{\"position\": [0,0,0], \"normal\": [0,1,0]}], \"occluders\": {\"objects\": [{\"asset\": "
         "\"nope\"}]}}",
         "/occluders/objects/0/asset"},
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        write_text(path, bad[i][0]);
        err[0] = 0;
        CHECK(lc_ref_mr_points_load(path, f.v, &in, err, sizeof err) != 0 && strstr(err, bad[i][1]),
              "bad points %zu: '%s'", i, err);
    }
    if (r) test_mr_visible(r, f.v);
    unlink(path);
    char p[160];
    snprintf(p, sizeof p, "%s/cube.obj", dir);
    unlink(p);
    snprintf(p, sizeof p, "%s/cube.mtl", dir);
    unlink(p);
    rmdir(dir);
    lc_ref_release(r);
    fixture_release(&f);
}

int main(void) {
    test_camera_model();
    test_png();
    test_poses();
    test_capture_box();
    test_capture_bounces();
    test_capture_vs_camera();
    test_mr_full();
    CHECK_DONE();
}
