/* SH helpers against closed forms and numeric integration. */
#include <math.h>

#include "check.h"
#include "util/rng.h"
#include "util/sh.h"

/* Spherical Fibonacci lattice: N nearly uniform directions, each with weight 4pi/N. */
static void fib_dir(int i, int n, float d[3]) {
    double z = 1.0 - (2.0 * i + 1.0) / n;
    double r = sqrt(fmax(0.0, 1.0 - z * z));
    double phi = i * M_PI * (3.0 - sqrt(5.0));
    d[0] = (float)(r * cos(phi));
    d[1] = (float)(r * sin(phi));
    d[2] = (float)z;
}

/* lc_sh_rotation_l2: for random rotations (and a reflection) and random coefficients,
 * f(r n) = sum c_local y(n) at random directions n. */
static void test_rotation_l2(void) {
    lc_rng rng = lc_rng_seed(42, 7);
    double worst = 0;
    for (int trial = 0; trial < 20; trial++) {
        float q[4], n2 = 0;
        for (int k = 0; k < 4; k++) {
            q[k] = lc_rng_float(&rng) * 2 - 1;
            n2 += q[k] * q[k];
        }
        float l = sqrtf(n2), x = q[0] / l, y = q[1] / l, z = q[2] / l, w = q[3] / l;
        float r[9] = {1 - 2 * (y * y + z * z), 2 * (x * y - z * w),     2 * (x * z + y * w),
                      2 * (x * y + z * w),     1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                      2 * (x * z - y * w),     2 * (y * z + x * w),     1 - 2 * (x * x + y * y)};
        if (trial == 19) /* a mirror: negate the first column */
            for (int row = 0; row < 3; row++) r[3 * row] = -r[3 * row];
        float m[9][9], cw[9], cl[9];
        lc_sh_rotation_l2(r, m);
        for (int j = 0; j < 9; j++) cw[j] = lc_rng_float(&rng) * 2 - 1;
        for (int i = 0; i < 9; i++) {
            cl[i] = 0;
            for (int j = 0; j < 9; j++) cl[i] += m[i][j] * cw[j];
        }
        for (int s = 0; s < 50; s++) {
            float n[3], wn[3], yl[9], yw[9];
            fib_dir(s * 7 + trial, 400, n);
            for (int k = 0; k < 3; k++) wn[k] = r[3 * k] * n[0] + r[3 * k + 1] * n[1] + r[3 * k + 2] * n[2];
            lc_sh_eval(3, n, yl);
            lc_sh_eval(3, wn, yw);
            double fw = 0, fl = 0;
            for (int j = 0; j < 9; j++) fw += cw[j] * yw[j], fl += cl[j] * yl[j];
            worst = fmax(worst, fabs(fw - fl));
        }
    }
    CHECK(worst < 1e-4, "lc_sh_rotation_l2: f(r n) vs rotated coefficients, worst %g", worst);
}

int main(void) {
    enum { N = 200000, B = 8, C = B * B };
    test_rotation_l2();
    /* Orthonormality: int y_i y_j dw = delta_ij. */
    static double gram[C][C];
    float y[C];
    for (int i = 0; i < N; i++) {
        float d[3];
        fib_dir(i, N, d);
        lc_sh_eval(B, d, y);
        for (int a = 0; a < C; a++)
            for (int b = a; b < C; b++) gram[a][b] += (double)y[a] * y[b] * (4 * M_PI / N);
    }
    double worst = 0;
    for (int a = 0; a < C; a++)
        for (int b = a; b < C; b++) worst = fmax(worst, fabs(gram[a][b] - (a == b ? 1.0 : 0.0)));
    CHECK(worst < 2e-3, "SH basis not orthonormal: worst Gram error %g", worst);

    /* Convention: band 1 = sqrt(3/4pi) (y, z, x); y_2^0 = sqrt(5/16pi)(3z^2 - 1). */
    float d[3] = {0.36f, 0.48f, 0.8f};
    lc_sh_eval(3, d, y);
    double k1 = sqrt(3 / (4 * M_PI));
    CHECK_NEAR(y[0], 0.5 / sqrt(M_PI), 1e-6);
    CHECK_NEAR(y[1], k1 * d[1], 1e-6);
    CHECK_NEAR(y[2], k1 * d[2], 1e-6);
    CHECK_NEAR(y[3], k1 * d[0], 1e-6);
    CHECK_NEAR(y[6], sqrt(5 / (16 * M_PI)) * (3 * d[2] * d[2] - 1), 1e-6);
    CHECK_NEAR(y[4], 0.5 * sqrt(15 / M_PI) * d[0] * d[1], 1e-6);
    CHECK_NEAR(y[8], 0.25 * sqrt(15 / M_PI) * (d[0] * d[0] - d[1] * d[1]), 1e-6);

    /* Cone ratio h_l vs numeric integration over a cone around +z. */
    double alphas[] = {0.01, 0.3, 1.0, M_PI / 2, 2.5};
    for (int ai = 0; ai < 5; ai++) {
        double ca = cos(alphas[ai]);
        for (int l = 0; l < B; l++) {
            double num = 0, omega = 0;
            const int M = 200000;
            for (int i = 0; i < M; i++) { /* midpoint rule in cos(theta) */
                double t = ca + (1 - ca) * (i + 0.5) / M;
                num += lc_sh_legendre(l, t);
                omega += 1;
            }
            double h = num / omega;
            CHECK(fabs(lc_sh_cone_ratio(l, ca) - h) < 1e-5, "cone ratio l=%d alpha=%g: %g vs %g", l, alphas[ai],
                  lc_sh_cone_ratio(l, ca), h);
        }
    }
    CHECK_NEAR(lc_sh_cone_ratio(1, 0.2), 0.6, 1e-12);

    /* Clamped-cosine factors: A_l = 2pi int_0^1 P_l(t) t dt. */
    for (int l = 0; l < B; l++) {
        const int M = 100000;
        double a = 0;
        for (int i = 0; i < M; i++) {
            double t = (i + 0.5) / M;
            a += lc_sh_legendre(l, t) * t / M;
        }
        a *= 2 * M_PI;
        CHECK(fabs(lc_sh_cosine_factor(l) - a) < 1e-6, "A_%d = %g, numeric %g", l, lc_sh_cosine_factor(l), a);
    }
    CHECK_NEAR(lc_sh_cosine_factor(2), M_PI / 4, 1e-12);
    CHECK_NEAR(lc_sh_cosine_factor(4), -M_PI / 24, 1e-12);

    /* Zonal rotation (PIC eq. 5, the runtime projection): a uniform cone of half-angle alpha
     * around any direction d projects to Omega * h_l(cos alpha) * y_lm(d), checked against
     * direct numeric integration of y_lm over the cone. */
    {
        lc_rng rng = lc_rng_seed(3, 0);
        double worst_rot = 0;
        for (int trial = 0; trial < 6; trial++) {
            float d[3];
            fib_dir((int)(lc_rng_float(&rng) * 999), 1000, d);
            double ca = cos(0.2 + 1.2 * lc_rng_float(&rng));
            double num[C] = {0};
            const int M = 400000;
            for (int i = 0; i < M; i++) {
                float w[3];
                fib_dir(i, M, w);
                if (w[0] * d[0] + w[1] * d[1] + w[2] * d[2] < ca) continue;
                float yy[C];
                lc_sh_eval(B, w, yy);
                for (int k = 0; k < C; k++) num[k] += yy[k] * (4 * M_PI / M);
            }
            float yd[C];
            lc_sh_eval(B, d, yd);
            double omega = 2 * M_PI * (1 - ca);
            for (int l = 0; l < B; l++)
                for (int k = l * l; k < (l + 1) * (l + 1); k++)
                    worst_rot = fmax(worst_rot, fabs(num[k] - omega * lc_sh_cone_ratio(l, ca) * yd[k]));
        }
        CHECK(worst_rot < 2e-3, "rotated cone projection differs from integration by %g", worst_rot);
    }

    /* The fast float path equals the generic evaluation. */
    for (int i = 0; i < 1000; i++) {
        float dd[3], ya[16], yb[16];
        fib_dir(i, 1000, dd);
        lc_sh_eval(4, dd, ya);
        lc_sh_eval_fast(4, dd[0], dd[1], dd[2], yb);
        for (int k = 0; k < 16; k++)
            if (fabsf(ya[k] - yb[k]) > 1e-5f) {
                CHECK(0, "fast SH coeff %d differs at dir %d: %g vs %g", k, i, yb[k], ya[k]);
                i = 1000;
                break;
            }
    }

    /* Irradiance of a uniform sky L=1 through SH: E = pi for any normal. */
    float n[3] = {0, 1, 0};
    lc_sh_eval(3, n, y);
    double e = lc_sh_cosine_factor(0) * (1.0 * sqrt(4 * M_PI)) * y[0];
    CHECK_NEAR(e, M_PI, 1e-6);
    CHECK_DONE();
}
