/* delta: how well an approximation reproduces the change an object makes (`lucent-ref delta`,
 * ref.h). An object changes a texel's light by a few percent, so the error of E itself would
 * hide the error of the change; this compares dE = E(with) - E(without) per texel. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "ref/ref.h"

int lc_ref_delta_lightmap(const float *a0, const float *a1, const lc_ref_result *r0, const lc_ref_result *r1,
                          double k_sigma, double floor_frac, lc_ref_delta_stats *out, float *delta_img) {
    memset(out, 0, sizeof *out);
    const size_t texels = (size_t)r0->width * r0->height;
    double mean_y = 0;
    uint32_t n_owned = 0;
    for (size_t i = 0; i < texels; i++)
        if (r0->texel_mask[i] == 1) {
            mean_y += lc_ref_luminance(r0->lightmap + 3 * i);
            n_owned++;
        }
    if (!n_owned) return -1;
    mean_y /= n_owned;
    out->floor = floor_frac * mean_y;
    double sum_abs_err = 0, sum_err = 0, sum_abs_ref = 0, sum_sigma = 0, neg[2] = {0, 0}, pos[2] = {0, 0};
    double vis_abs_err = 0, vis_abs_ref = 0;
    uint32_t agree = 0;
    for (size_t i = 0; i < texels; i++) {
        if (delta_img) delta_img[3 * i] = delta_img[3 * i + 1] = delta_img[3 * i + 2] = NAN;
        if (r0->texel_mask[i] != 1 || r1->texel_mask[i] != 1) continue;
        double dr = lc_ref_luminance(r1->lightmap + 3 * i) - lc_ref_luminance(r0->lightmap + 3 * i);
        double da = lc_ref_luminance(a1 + 3 * i) - lc_ref_luminance(a0 + 3 * i);
        double s0 = lc_ref_luminance(r0->lightmap_stderr + 3 * i), s1 = lc_ref_luminance(r1->lightmap_stderr + 3 * i);
        double sigma = sqrt(s0 * s0 + s1 * s1);
        if (!(fabs(dr) > k_sigma * sigma) || !(fabs(dr) > out->floor)) continue;
        out->n++;
        sum_abs_err += fabs(da - dr);
        sum_err += da - dr;
        sum_abs_ref += fabs(dr);
        sum_sigma += sigma;
        agree += da != 0 && (da > 0) == (dr > 0);
        double *acc = dr < 0 ? neg : pos;
        acc[0] += da;
        acc[1] += dr;
        if (dr < 0) out->n_neg++;
        else out->n_pos++;
        for (int k = 0; k < 3; k++) {
            out->rgb_approx[k] += a1[3 * i + k] - a0[3 * i + k];
            out->rgb_ref[k] += r1->lightmap[3 * i + k] - r0->lightmap[3 * i + k];
        }
        double y0 = lc_ref_luminance(r0->lightmap + 3 * i);
        /* Under the object: the reference is (nearly) black with it, the texel hidden. */
        if (lc_ref_luminance(r1->lightmap + 3 * i) <= 0.02 * y0) out->n_buried++;
        else {
            vis_abs_err += fabs(da - dr);
            vis_abs_ref += fabs(dr);
        }
        if (y0 > 0) out->max_rel_change = fmax(out->max_rel_change, fabs(dr) / y0);
        if (delta_img) {
            delta_img[3 * i] = (float)dr;
            delta_img[3 * i + 1] = (float)da;
            delta_img[3 * i + 2] = (float)(da - dr);
        }
    }
    if (!out->n) return -1;
    out->error = sum_abs_err / sum_abs_ref;
    out->error_unburied = vis_abs_ref > 0 ? vis_abs_err / vis_abs_ref : NAN;
    out->bias = sum_err / sum_abs_ref;
    out->sign_agree = (double)agree / out->n;
    out->neg_ratio = neg[1] != 0 ? neg[0] / neg[1] : NAN;
    out->pos_ratio = pos[1] != 0 ? pos[0] / pos[1] : NAN;
    out->ref_noise = sum_sigma / sum_abs_ref;
    out->mean_abs_ref = sum_abs_ref / out->n;
    return 0;
}

static void delta_num(char *buf, size_t cap, size_t *len, const char *name, double v) {
    if (*len >= cap) return;
    *len += (size_t)snprintf(buf + *len, cap - *len, "\"%s\": %.9g, ", name, isfinite(v) ? v : 0.0);
}

char *lc_ref_delta_json(const lc_ref_delta_stats *s) {
    size_t cap = 1024, len = 0;
    char *b = malloc(cap);
    if (!b) return NULL;
    len += (size_t)snprintf(b, cap, "{\"n\": %u, \"n_darker\": %u, \"n_brighter\": %u, \"n_buried\": %u, ", s->n,
                            s->n_neg, s->n_pos, s->n_buried);
    delta_num(b, cap, &len, "error", s->error);
    delta_num(b, cap, &len, "bias", s->bias);
    delta_num(b, cap, &len, "error_unburied", s->error_unburied);
    delta_num(b, cap, &len, "sign_agree", s->sign_agree);
    delta_num(b, cap, &len, "darker_ratio", s->neg_ratio);
    delta_num(b, cap, &len, "brighter_ratio", s->pos_ratio);
    delta_num(b, cap, &len, "ref_noise", s->ref_noise);
    delta_num(b, cap, &len, "mean_abs_ref", s->mean_abs_ref);
    delta_num(b, cap, &len, "max_rel_change", s->max_rel_change);
    delta_num(b, cap, &len, "floor", s->floor);
    if (len < cap)
        len += (size_t)snprintf(
            b + len, cap - len, "\"rgb_approx\": [%.6g, %.6g, %.6g], \"rgb_ref\": [%.6g, %.6g, %.6g]}",
            s->rgb_approx[0], s->rgb_approx[1], s->rgb_approx[2], s->rgb_ref[0], s->rgb_ref[1], s->rgb_ref[2]);
    if (len >= cap) {
        free(b);
        return NULL;
    }
    return b;
}
