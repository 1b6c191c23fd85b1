/* sh: real spherical harmonics, orthonormal, index i = l*l + l + m, bands l = 0..bands-1.
 * Convention: no Condon-Shortley phase, polar axis +z, azimuth from +x, so band 1 is
 * (y, z, x) * sqrt(3/4pi) (the order three.js and Ramamoorthi-Hanrahan use). */
#ifndef LC_SH_H
#define LC_SH_H

#define LC_SH_MAX_BANDS 8
#define LC_SH_MAX_COEFFS (LC_SH_MAX_BANDS * LC_SH_MAX_BANDS)

/* Evaluates all bands*bands basis functions at unit direction d into out. bands in 1..8. */
void lc_sh_eval(int bands, const float d[3], float *out);

/* Float evaluation for hot loops: closed-form polynomials up to 4 bands, lc_sh_eval above.
 * Same convention and values as lc_sh_eval (tested against it). */
static inline void lc_sh_eval_fast(int bands, float x, float y, float z, float *out) {
    if (bands > 4) {
        float d[3] = {x, y, z};
        lc_sh_eval(bands, d, out);
        return;
    }
    out[0] = 0.282094791774f;
    if (bands < 2) return;
    out[1] = 0.488602511903f * y;
    out[2] = 0.488602511903f * z;
    out[3] = 0.488602511903f * x;
    if (bands < 3) return;
    out[4] = 1.092548430592f * x * y;
    out[5] = 1.092548430592f * y * z;
    out[6] = 0.315391565253f * (3.0f * z * z - 1.0f);
    out[7] = 1.092548430592f * x * z;
    out[8] = 0.546274215296f * (x * x - y * y);
    if (bands < 4) return;
    float z2 = z * z;
    out[9] = 0.590043589927f * y * (3.0f * x * x - y * y);
    out[10] = 2.890611442641f * x * y * z;
    out[11] = 0.457045799464f * y * (5.0f * z2 - 1.0f);
    out[12] = 0.373176332590f * z * (5.0f * z2 - 3.0f);
    out[13] = 0.457045799464f * x * (5.0f * z2 - 1.0f);
    out[14] = 1.445305721321f * z * (x * x - y * y);
    out[15] = 0.590043589927f * x * (x * x - 3.0f * y * y);
}

/* Legendre polynomial P_l(x). */
double lc_sh_legendre(int l, double x);

/* Cone of half-angle alpha (cos_alpha given), uniform over its solid angle: the ratio of its
 * zonal band-l projection to its band-0 projection, h_l = (1/Omega) * int_cone P_l(cos t) dw.
 * h_0 = 1, h_1 = (1 + cos_alpha) / 2. A cone of radiance L toward d projects to
 * L * Omega * sum_lm h_l * y_lm(d) * y_lm. */
double lc_sh_cone_ratio(int l, double cos_alpha);

/* Clamped-cosine convolution factor A_l (pi, 2pi/3, pi/4, 0, -pi/24, ...):
 * irradiance E(n) = sum_lm A_l * L_lm * y_lm(n). */
double lc_sh_cosine_factor(int l);

/* Rotation of bands 0..2: for a frame whose axes are the columns of the orthogonal matrix r
 * (row-major; world = r * local; a reflection is allowed), out is the 9x9 matrix taking a
 * function's world coefficients to its local ones, c_local[i] = sum_j out[i][j] c_world[j],
 * so that f(r n) = sum c_local[i] y_i(n). Exact (rotations keep bands): a least-squares fit
 * on 16 fixed directions, in double. */
void lc_sh_rotation_l2(const float r[9], float out[9][9]);

#endif
