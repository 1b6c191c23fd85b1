/* The engine SH helpers (lucent_client.h, "Engine layouts") against each platform's own
 * published SH evaluation.
 *
 * For known radiance fields (a constant, directional lobes from 14 directions with a
 * different lobe per colour channel, random L2 fields), the SH a client receives is built as
 * the server builds it (radiance projected on lucent's basis, common/sh.h lc_sh_eval,
 * then convolved with the clamped cosine A_l, daemon/engine/cpu/transport_cpu.c "Grid"), sent in an
 * shgrid f32 keyframe and decoded by lc_client_view_apply. It is converted with the helper
 * for platform P and evaluated with P's formula, written out below with its source, at the
 * normal mapped into P's frame. That must equal lucent's own irradiance, lc_sh9_irradiance, at
 * the glTF normal (where P folds the Lambert 1/pi into its SH, pi times P's value), within
 * 1e-4 of the expected value, floored at 2% of the field's peak: the platforms publish their
 * constants to 6 digits (hello_ar's 0.136569 is 3.3e-6 off), which is up to ~7e-5 of a value
 * at 1% of the peak. Both sides are clamped at 0, as lc_sh9_irradiance and hello_ar are.
 *
 * Frames: lucent uses glTF axes (right-handed, +Y up, PROTOCOL.md / ../shared/DESIGN.md §3).
 *   Unity: left-handed, +Y up, +Z forward. KhronosGroup UnityGLTF
 *     Runtime/Plugins/GLTFSerialization/Schema/SchemaExtensions.cs `CoordinateSpaceConversionScale
 *     = (-1, 1, 1)` ("glTF: +Y up, +Z forward, -X right, right-handed; unity: +Y up, +Z forward,
 *     +X right, left-handed; multiply by a negative X scale"): glTF (x, y, z) -> Unity (-x, y, z).
 *   ARCore: world space right-handed, +Y up (developers.google.com/ar/reference/java/com/google/
 *     ar/core/Pose: "Coordinate system is right-handed, like OpenGL conventions"): identity.
 *   three.js: right-handed, +Y up; GLTFLoader keeps glTF axes: identity.
 *   ARKit: developer.apple.com/documentation/arkit/arconfiguration/worldalignment-swift.enum/
 *     gravity (right-handed, y up): identity. */
#include <stdint.h>

#include "check.h"
#include "lucent_client.h"
#include "lucent_proto.h"
#include "util/sh.h"

#define PI 3.14159265358979323846
#define TOL 1e-4
#define FLOOR 0.02 /* of the field's peak, see above */

/* ------------------------------------------------------------------------------------------
 * Radiance fields and the SH the server sends for them
 * ---------------------------------------------------------------------------------------- */

/* Radiance SH of one field: L[3*i + c] on lucent's basis (lc_sh_eval). */
typedef struct {
    const char *name;
    double L[27];
} field;

static void unit(double v[3]) {
    double n = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int k = 0; k < 3; k++) v[k] /= n;
}

/* A directional lobe (radiance a delta of irradiance w from direction d): L_i += w * y_i(d). */
static void add_lobe(field *f, int ch, const double d[3], double w) {
    float df[3] = {(float)d[0], (float)d[1], (float)d[2]}, y[9];
    lc_sh_eval(3, df, y);
    for (int i = 0; i < 9; i++) f->L[3 * i + ch] += w * y[i];
}

/* Constant radiance c: L_0 = c * sqrt(4 pi). */
static void add_constant(field *f, int ch, double c) { f->L[ch] += c * sqrt(4 * PI); }

static uint64_t rng_state = 0x9e3779b97f4a7c15ull;
static double rnd(void) { /* uniform in [-1, 1) */
    rng_state = rng_state * 6364136223846793005ull + 1442695040888963407ull;
    return (double)(rng_state >> 11) / 9007199254740992.0 * 2 - 1;
}

#define MAX_FIELDS 32
static field fields[MAX_FIELDS];
static int n_fields;

static void make_fields(void) {
    field *f = &fields[n_fields++];
    f->name = "constant (1, 0.5, 2)";
    add_constant(f, 0, 1.0);
    add_constant(f, 1, 0.5);
    add_constant(f, 2, 2.0);

    static const double dirs[][3] = {{1, 0, 0},  {-1, 0, 0},  {0, 1, 0},     {0, -1, 0},     {0, 0, 1},
                                     {0, 0, -1}, {1, 2, 3},   {-2, 1, -0.5}, {0.3, -1, 0.8}, {1, 1, 0},
                                     {-1, 0, 1}, {0, -1, -1}, {-3, -1, 2},   {2, -3, -1}};
    static char names[14][64];
    for (int k = 0; k < 14; k++) {
        f = &fields[n_fields++];
        double d[3] = {dirs[k][0], dirs[k][1], dirs[k][2]};
        unit(d);
        /* a different field per channel, so a channel or axis swap shows: red from d, green from
         * d with its axes cycled, blue a weaker lobe from d over a constant */
        double d2[3] = {d[1], d[2], d[0]};
        add_lobe(f, 0, d, 1.0);
        add_lobe(f, 1, d2, 0.7);
        add_lobe(f, 2, d, 0.4);
        add_constant(f, 2, 0.05);
        snprintf(names[k], sizeof names[k], "lobe from (%.2f, %.2f, %.2f)", d[0], d[1], d[2]);
        f->name = names[k];
    }

    for (int k = 0; k < 4; k++) {
        f = &fields[n_fields++];
        f->name = k < 2 ? "random L2 (positive)" : "random L2 (with negative regions)";
        for (int i = 0; i < 27; i++) f->L[i] = 0.5 * rnd();
        for (int ch = 0; ch < 3; ch++) f->L[ch] += k < 2 ? 3.0 : 0.4; /* DC large enough: no clamping */
    }
}

static uint8_t frame_buf[1 << 16];

/* The server's grid SH for every field (E_i = A_l * L_i, transport_cpu.c), through an shgrid
 * f32 keyframe and the client's decoder: received[27 * k + j] for field k. */
static void received_sh(float *received) {
    float payload[MAX_FIELDS * 27];
    for (int k = 0; k < n_fields; k++)
        for (int i = 0; i < 9; i++) {
            int l = i == 0 ? 0 : i < 4 ? 1 : 2;
            for (int ch = 0; ch < 3; ch++)
                payload[27 * k + 3 * i + ch] = (float)(lc_sh_cosine_factor(l) * fields[k].L[3 * i + ch]);
        }
    lc_frame_header h;
    memset(&h, 0, sizeof h);
    h.version = 1;
    h.stream = LC_STREAM_SHGRID;
    h.encoding = LC_ENC_F32;
    h.flags = LC_FRAME_KEYFRAME;
    h.revision = 1;
    h.sequence = 1;
    h.width = (uint32_t)n_fields;
    h.height = 1;
    h.depth = 1;
    h.payload_length = (uint32_t)(n_fields * 27 * sizeof(float));
    size_t n = lc_frame_write(&h, NULL, payload, frame_buf, sizeof frame_buf);
    lc_client_view *v = lc_client_view_create();
    lc_client_frame fr;
    char err[256] = "";
    int rc = lc_client_view_apply(v, frame_buf, n, &fr, err, sizeof err);
    CHECK(rc == 0 && fr.value_count == (size_t)n_fields * 27, "shgrid keyframe: rc %d %s", rc, err);
    if (rc == 0) memcpy(received, fr.values, (size_t)n_fields * 27 * sizeof(float));
    lc_client_view_release(v);
}

/* Test normals (glTF frame): the axes, diagonals and a Fibonacci sphere. */
#define N_NORMALS (26 + 200)
static double normals[N_NORMALS][3];

static void make_normals(void) {
    int n = 0;
    for (int x = -1; x <= 1; x++)
        for (int y = -1; y <= 1; y++)
            for (int z = -1; z <= 1; z++) {
                if (!x && !y && !z) continue;
                normals[n][0] = x, normals[n][1] = y, normals[n][2] = z;
                unit(normals[n++]);
            }
    for (int k = 0; k < 200; k++, n++) {
        double zz = 1 - (2 * k + 1) / 200.0, r = sqrt(1 - zz * zz), phi = k * PI * (3 - sqrt(5.0));
        normals[n][0] = r * cos(phi), normals[n][1] = zz, normals[n][2] = r * sin(phi);
    }
}

/* ------------------------------------------------------------------------------------------
 * The platforms' formulas
 * ---------------------------------------------------------------------------------------- */

/* three.js, src/math/SphericalHarmonics3.js `getIrradianceAt( normal, target )` (the same
 * polynomial as the light-probe shader, src/renderers/shaders/ShaderChunk/lights_pars_begin
 * `shGetIrradianceAt`), coefficients[i] = Vector3 (fromArray: 3*i .. 3*i+2):
 *   target = c0 * 0.886227                                        // pi * 0.282095
 *          + c1 * 2.0 * 0.511664 * y + c2 * 2.0 * 0.511664 * z + c3 * 2.0 * 0.511664 * x
 *          + c4 * 2.0 * 0.429043 * x * y + c5 * 2.0 * 0.429043 * y * z
 *          + c6 * ( 0.743125 * z * z - 0.247708 ) + c7 * 2.0 * 0.429043 * x * z
 *          + c8 * 0.429043 * ( x * x - y * y )
 * The irradiance E (no clamp). */
static void threejs_getIrradianceAt(const float c[27], const double n[3], double out[3]) {
    const double x = n[0], y = n[1], z = n[2];
    for (int ch = 0; ch < 3; ch++) {
        const float *k = c + ch;
        out[ch] = k[0] * 0.886227 + k[3] * 2.0 * 0.511664 * y + k[6] * 2.0 * 0.511664 * z + k[9] * 2.0 * 0.511664 * x +
            k[12] * 2.0 * 0.429043 * x * y + k[15] * 2.0 * 0.429043 * y * z + k[18] * (0.743125 * z * z - 0.247708) +
            k[21] * 2.0 * 0.429043 * x * z + k[24] * 0.429043 * (x * x - y * y);
    }
}

/* Unity. The shader constants from a SphericalHarmonicsL2 `sh[c, i]` (= planar 9*c + i):
 * Unity-Technologies/Graphics, com.unity.render-pipelines.high-definition/Runtime/Lighting/
 * SphericalHarmonics.cs `SphericalHarmonicMath.PackCoefficients` (Peter-Pike Sloan's
 * SetSHEMapConstants layout, what the built-in pipeline uploads as unity_SHAr..unity_SHC):
 *   SHA[c] = (sh[c,3], sh[c,1], sh[c,2], sh[c,0] - sh[c,6])
 *   SHB[c] = (sh[c,4], sh[c,5], sh[c,6] * 3, sh[c,7])
 *   SHC    = (sh[0,8], sh[1,8], sh[2,8], 1)
 * and their evaluation, UnityCG.cginc (SRP: ShaderLibrary/EntityLighting.hlsl)
 *   SHEvalLinearL0L1(normal): x.c = dot(unity_SHAc, float4(normal, 1))
 *   SHEvalLinearL2(normal):   vB = normal.xyzz * normal.yzzx; x1.c = dot(unity_SHBc, vB);
 *                             vC = normal.x*normal.x - normal.y*normal.y; x2 = unity_SHC.rgb * vC
 *   ShadeSH9 = SHEvalLinearL0L1 + SHEvalLinearL2
 * ShadeSH9 is the radiance a white Lambertian surface reflects (Unity multiplies it by the
 * albedo): E / pi. The normal is in Unity's (left-handed) world frame. */
static void unity_pack(const float sh[27], double sha[3][4], double shb[3][4], double shc[4]) {
#define SH(c, i) ((double)sh[9 * (c) + (i)])
    for (int c = 0; c < 3; c++) {
        sha[c][0] = SH(c, 3), sha[c][1] = SH(c, 1), sha[c][2] = SH(c, 2), sha[c][3] = SH(c, 0) - SH(c, 6);
        shb[c][0] = SH(c, 4), shb[c][1] = SH(c, 5), shb[c][2] = SH(c, 6) * 3.0, shb[c][3] = SH(c, 7);
    }
    shc[0] = SH(0, 8), shc[1] = SH(1, 8), shc[2] = SH(2, 8), shc[3] = 1.0;
#undef SH
}

static void unity_ShadeSH9(const float sh[27], const double n[3], double out[3]) {
    double sha[3][4], shb[3][4], shc[4];
    unity_pack(sh, sha, shb, shc);
    const double n4[4] = {n[0], n[1], n[2], 1.0};
    const double vB[4] = {n[0] * n[1], n[1] * n[2], n[2] * n[2], n[2] * n[0]};
    const double vC = n[0] * n[0] - n[1] * n[1];
    for (int c = 0; c < 3; c++) {
        double l0l1 = 0, l2 = 0;
        for (int k = 0; k < 4; k++) {
            l0l1 += sha[c][k] * n4[k];
            l2 += shb[c][k] * vB[k];
        }
        out[c] = l0l1 + l2 + shc[c] * vC;
    }
}

/* Unity's SphericalHarmonicsL2 convention (same file): `UndoCosineRescaling` divides sh[c, i]
 * by kNormalizationConstants {c0, -c1, c1, -c1, c2, -c2, c3, -c2, c4} (c0 = 1/2 sqrt(1/pi),
 * c1 = 1/3 sqrt(3/pi), c2 = 1/8 sqrt(15/pi), c3 = 1/16 sqrt(5/pi), c4 = 1/16 sqrt(15/pi)) "to
 * obtain the canonical values of SH" (radiance), `PremultiplyCoefficients` multiplies by the
 * basis constants {k0, -k1, k1, -k1, k2, -k2, k3, -k2, k4}; packed and evaluated as above that
 * gives the radiance in direction n (HDRP's use for volumetric lighting). */
static void unity_hdrp_radiance_form(const float sh[27], float out[27]) {
    static const double c0 = 0.28209479177387814347, c1 = 0.32573500793527994772, c2 = 0.27313710764801976764,
                        c3 = 0.07884789131313000151, c4 = 0.13656855382400988382;
    static const double k0 = 0.28209479177387814347, k1 = 0.48860251190291992159, k2 = 1.09254843059207907054,
                        k3 = 0.31539156525252000603, k4 = 0.54627421529603953527;
    const double inv_norm[9] = {1 / c0, -1 / c1, 1 / c1, -1 / c1, 1 / c2, -1 / c2, 1 / c3, -1 / c2, 1 / c4};
    const double ks[9] = {k0, -k1, k1, -k1, k2, -k2, k3, -k2, k4};
    for (int c = 0; c < 3; c++)
        for (int i = 0; i < 9; i++) out[9 * c + i] = (float)(sh[9 * c + i] * inv_norm[i] * ks[i]);
}

/* ARCore. google-ar/arcore-android-sdk samples/hello_ar_java HelloArActivity
 * `updateSphericalHarmonicsCoefficients(lightEstimate.getEnvironmentalHdrAmbientSphericalHarmonics())`:
 *   shader[i] = coefficients[i] * sphericalHarmonicFactors[i / 3], i < 27, with
 *   sphericalHarmonicFactors = {0.282095, -0.325735, 0.325735, -0.325735, 0.273137, -0.273137,
 *                               0.078848, -0.273137, 0.136569}
 *   ("1. the normalized SH basis functions, 2. the Lambertian diffuse BRDF factor (1/pi),
 *    3. a <cos> convolution")
 * then assets/shaders/environmental_hdr.frag `Pbr_CalculateDiffuseEnvironmentalRadiance(normal,
 * coefficients)` with the world-space normal:
 *   max(c[0] + c[1]*(n.y) + c[2]*(n.z) + c[3]*(n.x) + c[4]*(n.y*n.x) + c[5]*(n.y*n.z)
 *       + c[6]*(3.0*n.z*n.z - 1.0) + c[7]*(n.z*n.x) + c[8]*(n.x*n.x - n.y*n.y), 0.0)
 * which is multiplied by the albedo ("the lambertian diffuse BRDF term (1/pi) is baked into"
 * the factors): E / pi. */
static void arcore_hello_ar(const float coefficients[27], const double n[3], double out[3]) {
    static const double factors[9] = {0.282095,  -0.325735, 0.325735,  -0.325735, 0.273137,
                                      -0.273137, 0.078848,  -0.273137, 0.136569};
    double c[27];
    for (int i = 0; i < 27; i++) c[i] = coefficients[i] * factors[i / 3];
    const double x = n[0], y = n[1], z = n[2];
    for (int ch = 0; ch < 3; ch++) {
        const double *k = c + ch;
        double r = k[0] + k[3] * y + k[6] * z + k[9] * x + k[12] * (y * x) + k[15] * (y * z) +
            k[18] * (3.0 * z * z - 1.0) + k[21] * (z * x) + k[24] * (x * x - y * y);
        out[ch] = r > 0 ? r : 0;
    }
}

/* Normals into each platform's frame (see the top of the file). */
static void to_unity(const double n[3], double u[3]) { u[0] = -n[0], u[1] = n[1], u[2] = n[2]; }
static void identity(const double n[3], double u[3]) { u[0] = n[0], u[1] = n[1], u[2] = n[2]; }

/* ------------------------------------------------------------------------------------------
 * The comparison
 * ---------------------------------------------------------------------------------------- */

typedef void (*convert_fn)(const float irradiance[27], float out[27]);
typedef void (*eval_fn)(const float coeffs[27], const double n[3], double out[3]);
typedef void (*frame_fn)(const double n[3], double out[3]);

/* Worst |scale * P(map(n)) - E_lucent(n)| / max(E_lucent(n), floor * the field's peak) over
 * normals and channels, both clamped at 0. *at gets the normal index of the worst. */
static double worst_error(const float e[27], convert_fn conv, eval_fn eval, frame_fn map, double scale, double floor,
                          int *at) {
    float conv_out[27];
    conv(e, conv_out);
    double peak = 0, ref[N_NORMALS][3];
    for (int k = 0; k < N_NORMALS; k++) {
        float nf[3] = {(float)normals[k][0], (float)normals[k][1], (float)normals[k][2]}, rgb[3];
        lc_sh9_irradiance(e, nf, rgb);
        for (int ch = 0; ch < 3; ch++) {
            ref[k][ch] = rgb[ch];
            peak = fmax(peak, rgb[ch]);
        }
    }
    double worst = 0;
    for (int k = 0; k < N_NORMALS; k++) {
        double m[3], got[3];
        map(normals[k], m);
        eval(conv_out, m, got);
        for (int ch = 0; ch < 3; ch++) {
            double g = fmax(0.0, got[ch] * scale);
            double d = fabs(g - ref[k][ch]) / fmax(ref[k][ch], floor * peak);
            if (!(d <= worst)) { /* NaN counts */
                worst = d;
                if (at) *at = k;
            }
        }
    }
    return worst;
}

/* One platform over every field; returns the worst error and checks it against TOL. */
static double check_platform(const char *platform, const float *received, convert_fn conv, eval_fn eval, frame_fn map,
                             double scale) {
    double all = 0;
    for (int f = 0; f < n_fields; f++) {
        int at = 0;
        double w = worst_error(received + 27 * f, conv, eval, map, scale, FLOOR, &at);
        CHECK(w <= TOL, "%s, field %s: relative error %.3g at normal (%.3f, %.3f, %.3f) (allowed %g)", platform,
              fields[f].name, w, normals[at][0], normals[at][1], normals[at][2], TOL);
        all = fmax(all, w);
    }
    fprintf(stderr, "%-44s worst relative error %.2e over %d fields x %d normals\n", platform, all, n_fields,
            N_NORMALS);
    return all;
}

/* Unity through HDRP's canonical (radiance) form: the radiance field itself, as lucent's
 * server projected it (lc_sh_eval over the radiance SH), at the same normal. */
static void check_unity_radiance(const float *received) {
    double all = 0;
    for (int f = 0; f < n_fields; f++) {
        float unity[27], rad_form[27];
        lc_sh9_to_unity(received + 27 * f, unity);
        unity_hdrp_radiance_form(unity, rad_form);
        double peak = 0, ref[N_NORMALS][3];
        for (int k = 0; k < N_NORMALS; k++) {
            float nf[3] = {(float)normals[k][0], (float)normals[k][1], (float)normals[k][2]}, y[9];
            lc_sh_eval(3, nf, y);
            for (int ch = 0; ch < 3; ch++) {
                double L = 0;
                for (int i = 0; i < 9; i++) L += fields[f].L[3 * i + ch] * y[i];
                ref[k][ch] = fmax(0.0, L);
                peak = fmax(peak, ref[k][ch]);
            }
        }
        double worst = 0;
        for (int k = 0; k < N_NORMALS; k++) {
            double m[3], got[3];
            to_unity(normals[k], m);
            unity_ShadeSH9(rad_form, m, got);
            for (int ch = 0; ch < 3; ch++) {
                double d = fabs(fmax(0.0, got[ch]) - ref[k][ch]) / fmax(ref[k][ch], FLOOR * peak);
                if (!(d <= worst)) worst = d;
            }
        }
        CHECK(worst <= TOL, "Unity HDRP radiance form, field %s: relative error %.3g", fields[f].name, worst);
        all = fmax(all, worst);
    }
    fprintf(stderr, "%-44s worst relative error %.2e\n", "Unity UndoCosineRescaling+Premultiply (L)", all);
}

/* The layouts the README prescribed before issue 13, evaluated the same way: they must be
 * rejected, or this harness could not tell a right layout from a wrong one. */
static void old_unity(const float e[27], float out[27]) {
    float r[27];
    lc_sh9_irradiance_to_radiance(e, r);
    lc_sh9_to_planar(r, out); /* "lc_sh9_to_planar() of the radiance form" */
}
static void old_arcore(const float e[27], float out[27]) {
    lc_sh9_irradiance_to_radiance(e, out); /* "radiance form" */
}

/* Worst error over the fields, relative to each field's peak irradiance. */
static double worst_over_fields(const float *received, convert_fn conv, eval_fn eval, frame_fn map, double scale) {
    double all = 0;
    for (int f = 0; f < n_fields; f++)
        all = fmax(all, worst_error(received + 27 * f, conv, eval, map, scale, 1.0, NULL));
    return all;
}

int main(void) {
    make_fields();
    make_normals();
    float received[MAX_FIELDS * 27];
    memset(received, 0, sizeof received);
    received_sh(received);

    /* lucent's own evaluation agrees with the radiance it was made from (sanity of the harness):
     * a lobe of unit irradiance straight on gives E = 1/4 + 1/2 + 5/16 = 1.0625 (L2 truncation) */
    {
        float rgb[3];
        const float nx[3] = {1, 0, 0};
        lc_sh9_irradiance(received + 27 * 1, nx, rgb);
        CHECK_NEAR(rgb[0], 1.0625, 1e-5);
        const float up[3] = {0, 1, 0};
        lc_sh9_irradiance(received, up, rgb);
        CHECK_NEAR(rgb[0], PI * 1.0, 1e-5); /* constant radiance 1: E = pi */
        CHECK_NEAR(rgb[2], PI * 2.0, 1e-5);
    }

    check_platform("three.js SphericalHarmonics3.getIrradianceAt", received, lc_sh9_to_threejs, threejs_getIrradianceAt,
                   identity, 1.0);
    check_platform("Unity SphericalHarmonicsL2 -> ShadeSH9 (x pi)", received, lc_sh9_to_unity, unity_ShadeSH9, to_unity,
                   PI);
    check_unity_radiance(received);
    check_platform("ARCore hello_ar environmental_hdr (x pi)", received, lc_sh9_to_arcore, arcore_hello_ar, identity,
                   PI);

    /* Unity ambient colour: constant radiance c is sh[c, 0] = c, nothing else (what
     * SphericalHarmonicsL2.AddAmbientLight(c) adds) */
    {
        float unity[27];
        lc_sh9_to_unity(received, unity);
        CHECK_NEAR(unity[0], 1.0, 1e-6);
        CHECK_NEAR(unity[9], 0.5, 1e-6);
        CHECK_NEAR(unity[18], 2.0, 1e-6);
        int rest_zero = 1;
        for (int c = 0; c < 3; c++)
            for (int i = 1; i < 9; i++) rest_zero &= fabsf(unity[9 * c + i]) < 1e-7f;
        CHECK(rest_zero, "Unity ambient: only sh[c, 0] set");
    }

    /* ARKit: Apple documents only the layout of ARDirectionalLightEstimate.
     * sphericalHarmonicsCoefficients ("second-level spherical harmonics in separate red, green,
     * and blue data planes ... 3 sets of 9 coefficients", developer.apple.com/documentation/arkit/
     * ardirectionallightestimate/spherical-harmonics-coefficients), no basis or evaluation
     * formula: the plane layout, lucent's basis and scale, same axes. */
    {
        int ok = 1;
        for (int f = 0; f < n_fields; f++) {
            float arkit[27];
            lc_sh9_to_arkit(received + 27 * f, arkit);
            for (int c = 0; c < 3; c++)
                for (int i = 0; i < 9; i++) ok &= arkit[9 * c + i] == received[27 * f + 3 * i + c];
        }
        CHECK(ok, "ARKit: plane c holds coefficient i of channel c at 9*c + i");
    }

    /* The harness rejects the old prescriptions (and reports by how much, relative to each
     * field's peak irradiance). */
    double old_u = worst_over_fields(received, old_unity, unity_ShadeSH9, to_unity, PI);
    double old_u_raw = worst_over_fields(received, old_unity, unity_ShadeSH9, to_unity, 1.0);
    double old_u_same_axes = worst_over_fields(received, lc_sh9_to_unity, unity_ShadeSH9, identity, PI);
    double old_a = worst_over_fields(received, old_arcore, arcore_hello_ar, identity, PI);
    fprintf(stderr,
            "of the peak: old Unity (planar radiance form) %.0f%% (ShadeSH9 x pi), %.0f%% (ShadeSH9 "
            "read as E); Unity without the x mirror %.0f%%; old ARCore (radiance form) %.0f%%\n",
            100 * old_u, 100 * old_u_raw, 100 * old_u_same_axes, 100 * old_a);
    CHECK(old_u > 0.1 && old_u_raw > 0.1, "old Unity layout must fail: %g %g", old_u, old_u_raw);
    CHECK(old_u_same_axes > 0.1, "Unity without the handedness change must fail: %g", old_u_same_axes);
    CHECK(old_a > 0.1, "old ARCore layout must fail: %g", old_a);
    CHECK_DONE();
}
