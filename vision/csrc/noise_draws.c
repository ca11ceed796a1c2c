/* The draws of the rotation noise (vision/noise.py rotation_noise_batch), for many
 * numpy generators in one call.
 *
 * Generator.standard_normal(out=...) and Generator.random(out=...) fill their output
 * with numpy's own random_standard_normal_fill and random_standard_uniform_fill (the C
 * API of numpy.random, numpy/random/distributions.h, linked from numpy's
 * libnpyrandom.a); this calls the same two functions on each generator's bit
 * generator, in the same order, so the numbers and the generators' states afterwards
 * are those of the Python loop, to the last bit. The generators' locks are not taken:
 * the caller holds the generators and uses them from one thread.
 */
#include <stddef.h>
#include <stdint.h>

/* numpy/random/bitgen.h (declared here: distributions.h needs Python.h) */
typedef struct bitgen {
    void *state;
    uint64_t (*next_uint64)(void *st);
    uint32_t (*next_uint32)(void *st);
    double (*next_double)(void *st);
    uint64_t (*next_raw)(void *st);
} bitgen_t;

void random_standard_normal_fill(bitgen_t *bitgen_state, intptr_t cnt, double *out);
void random_standard_uniform_fill(bitgen_t *bitgen_state, intptr_t cnt, double *out);

/* For each generator k of n: 3 m standard normals into axes[3 m k ...], then m uniforms
 * in [0, 1) into fractions[m k ...]. */
void hexapod_rotation_draws(bitgen_t **generators, int64_t n, int64_t m, double *axes,
                            double *fractions)
{
    for (int64_t k = 0; k < n; k++) {
        random_standard_normal_fill(generators[k], (intptr_t)(3 * m), axes + 3 * m * k);
        random_standard_uniform_fill(generators[k], (intptr_t)m, fractions + m * k);
    }
}
