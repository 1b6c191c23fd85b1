/* rng: deterministic sequences for bakes. Everything seeded by (seed, item index) so results
 * do not depend on thread scheduling. */
#ifndef LC_RNG_H
#define LC_RNG_H
#include <stdint.h>

/* SplitMix64: a good 64-bit mix; also a stream generator. */
static inline uint64_t lc_mix64(uint64_t x) {
    x += 0x9E3779B97F4A7C15ull;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
    return x ^ (x >> 31);
}

typedef struct {
    uint64_t state;
} lc_rng;

static inline lc_rng lc_rng_seed(uint64_t seed, uint64_t stream) {
    return (lc_rng){lc_mix64(seed ^ lc_mix64(stream + 0x1234567ull))};
}
static inline uint64_t lc_rng_next(lc_rng *r) {
    r->state += 0x9E3779B97F4A7C15ull;
    uint64_t z = r->state;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}
/* Uniform float in [0, 1). */
static inline float lc_rng_float(lc_rng *r) { return (float)(lc_rng_next(r) >> 40) * (1.0f / 16777216.0f); }

/* Radical inverse in base b (Halton component), for index i. */
static inline double lc_halton(uint64_t i, uint32_t base) {
    double f = 1.0, r = 0.0;
    while (i > 0) {
        f /= base;
        r += f * (double)(i % base);
        i /= base;
    }
    return r;
}

#endif
