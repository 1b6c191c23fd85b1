/* sh: real spherical harmonics, orthonormal, index i = l*l + l + m, bands l = 0..bands-1.
 * Convention: no Condon-Shortley phase, polar axis +z, azimuth from +x, so band 1 is
 * (y, z, x) * sqrt(3/4pi) (the order three.js and Ramamoorthi-Hanrahan use). */
#ifndef LC_SH_H
#define LC_SH_H

#define LC_SH_MAX_BANDS 8
#define LC_SH_MAX_COEFFS (LC_SH_MAX_BANDS * LC_SH_MAX_BANDS)

/* Evaluates all bands*bands basis functions at unit direction d into out. bands in 1..8. */
void lc_sh_eval(int bands, const float d[3], float *out);

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

#endif
