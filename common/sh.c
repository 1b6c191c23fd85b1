#include "util/sh.h"

#include <math.h>
#include <pthread.h>

/* K_lm = sqrt((2l+1)/(4pi) * (l-m)!/(l+m)!) at l*l + l + m (m >= 0), computed once. */
static double sh_k[LC_SH_MAX_COEFFS];
static pthread_once_t sh_k_once = PTHREAD_ONCE_INIT;

static void sh_k_init(void) {
    for (int l = 0; l < LC_SH_MAX_BANDS; l++)
        for (int m = 0; m <= l; m++) {
            double ratio = 1.0;
            for (int k = l - m + 1; k <= l + m; k++) ratio /= (double)k;
            sh_k[l * l + l + m] = sqrt((2 * l + 1) / (4.0 * M_PI) * ratio);
        }
}

void lc_sh_eval(int bands, const float d[3], float *out) {
    pthread_once(&sh_k_once, sh_k_init);
    const double x = d[0], y = d[1], z = d[2];
    /* Q[l][m]: associated Legendre P_l^m(z) with the sin^m(theta) factor removed. */
    double q[LC_SH_MAX_BANDS][LC_SH_MAX_BANDS];
    /* (x + i y)^m = sin^m(theta) * (cos m phi + i sin m phi). */
    double re[LC_SH_MAX_BANDS], im[LC_SH_MAX_BANDS];
    if (bands < 1) return;
    if (bands > LC_SH_MAX_BANDS) bands = LC_SH_MAX_BANDS;
    re[0] = 1.0;
    im[0] = 0.0;
    for (int m = 1; m < bands; m++) {
        re[m] = re[m - 1] * x - im[m - 1] * y;
        im[m] = re[m - 1] * y + im[m - 1] * x;
    }
    for (int m = 0; m < bands; m++) {
        double pmm = 1.0;
        for (int k = 1; k <= m; k++) pmm *= (double)(2 * k - 1);
        q[m][m] = pmm;
        if (m + 1 < bands) q[m + 1][m] = z * (2 * m + 1) * pmm;
        for (int l = m + 2; l < bands; l++)
            q[l][m] = ((2 * l - 1) * z * q[l - 1][m] - (l + m - 1) * q[l - 2][m]) / (double)(l - m);
    }
    for (int l = 0; l < bands; l++) {
        for (int m = 0; m <= l; m++) {
            double k_lm = sh_k[l * l + l + m];
            if (m == 0) {
                out[l * l + l] = (float)(k_lm * q[l][0]);
            } else {
                double s = M_SQRT2 * k_lm * q[l][m];
                out[l * l + l + m] = (float)(s * re[m]);
                out[l * l + l - m] = (float)(s * im[m]);
            }
        }
    }
}

double lc_sh_legendre(int l, double x) {
    if (l == 0) return 1.0;
    double p0 = 1.0, p1 = x;
    for (int k = 2; k <= l; k++) {
        double p2 = ((2 * k - 1) * x * p1 - (k - 1) * p0) / k;
        p0 = p1;
        p1 = p2;
    }
    return p1;
}

double lc_sh_cone_ratio(int l, double cos_alpha) {
    if (l == 0) return 1.0;
    double one_minus = 1.0 - cos_alpha;
    if (one_minus < 1e-4) /* series: P_l(1 - e) ~ 1 - l(l+1) e / 2, avoids cancellation */
        return 1.0 - l * (l + 1) * one_minus / 4.0;
    /* int_c^1 P_l = (P_{l-1}(c) - P_{l+1}(c)) / (2l + 1) */
    double integral = (lc_sh_legendre(l - 1, cos_alpha) - lc_sh_legendre(l + 1, cos_alpha)) / (2 * l + 1);
    return integral / one_minus;
}

double lc_sh_cosine_factor(int l) {
    if (l == 0) return M_PI;
    if (l == 1) return 2.0 * M_PI / 3.0;
    if (l % 2 == 1) return 0.0;
    /* A_l = 2 pi * (-1)^(l/2 - 1) / ((l + 2)(l - 1)) * l! / (2^l ((l/2)!)^2) */
    double fact_ratio = 1.0; /* l! / ((l/2)!)^2 / 2^l */
    for (int k = 1; k <= l; k++) fact_ratio *= k;
    double half = 1.0;
    for (int k = 1; k <= l / 2; k++) half *= k;
    fact_ratio /= half * half * pow(2.0, l);
    double sign = ((l / 2 - 1) % 2 == 0) ? 1.0 : -1.0;
    return 2.0 * M_PI * sign / ((l + 2) * (l - 1)) * fact_ratio;
}

/* Gauss-Jordan inverse of a 9x9 (symmetric positive definite here: well conditioned). */
static void sh_invert9(double a[9][9], double inv[9][9]) {
    for (int i = 0; i < 9; i++)
        for (int j = 0; j < 9; j++) inv[i][j] = i == j;
    for (int c = 0; c < 9; c++) {
        int piv = c;
        for (int r = c + 1; r < 9; r++)
            if (fabs(a[r][c]) > fabs(a[piv][c])) piv = r;
        for (int k = 0; k < 9; k++) {
            double t = a[c][k];
            a[c][k] = a[piv][k];
            a[piv][k] = t;
            t = inv[c][k];
            inv[c][k] = inv[piv][k];
            inv[piv][k] = t;
        }
        double d = a[c][c];
        for (int k = 0; k < 9; k++) {
            a[c][k] /= d;
            inv[c][k] /= d;
        }
        for (int r = 0; r < 9; r++) {
            if (r == c) continue;
            double f = a[r][c];
            for (int k = 0; k < 9; k++) {
                a[r][k] -= f * a[c][k];
                inv[r][k] -= f * inv[c][k];
            }
        }
    }
}

void lc_sh_rotation_l2(const float r[9], float out[9][9]) {
    enum { N = 16 };
    double y[N][9], yr[N][9];
    for (int i = 0; i < N; i++) { /* Fibonacci sphere */
        double z = 1.0 - (2.0 * i + 1.0) / N, s = sqrt(1.0 - z * z), phi = 2.399963229728653 * i;
        float n[3] = {(float)(s * cos(phi)), (float)(s * sin(phi)), (float)z}, w[3];
        for (int k = 0; k < 3; k++) w[k] = r[3 * k] * n[0] + r[3 * k + 1] * n[1] + r[3 * k + 2] * n[2];
        float a[9], b[9];
        lc_sh_eval(3, n, a);
        lc_sh_eval(3, w, b);
        for (int k = 0; k < 9; k++) {
            y[i][k] = a[k];
            yr[i][k] = b[k];
        }
    }
    double ata[9][9], inv[9][9];
    for (int a = 0; a < 9; a++)
        for (int b = 0; b < 9; b++) {
            ata[a][b] = 0;
            for (int i = 0; i < N; i++) ata[a][b] += y[i][a] * y[i][b];
        }
    sh_invert9(ata, inv);
    /* out = inv * Y^T * Yr: column j is the local fit of world basis function j. */
    for (int a = 0; a < 9; a++)
        for (int j = 0; j < 9; j++) {
            double sum = 0;
            for (int b = 0; b < 9; b++) {
                double ytyr = 0;
                for (int i = 0; i < N; i++) ytyr += y[i][b] * yr[i][j];
                sum += inv[a][b] * ytyr;
            }
            out[a][j] = (float)sum;
        }
}
