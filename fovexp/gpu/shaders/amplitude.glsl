// Noise amplitude and the clipping control: fovexp/amplitude.py (paper section 4.2, eqs. 7-9
// as corrected in docs/METHOD.md, 3.1-3.2; the release's smoothing and gain, docs/METHOD.md, 5.7).

#include "pyramids.glsl"

uniform float attenuation;
uniform int lap_top;                                  // coarsest |L_k| level built
uniform int lap_offset[MAX_LAPLACIAN_LEVEL + 1];      // level k at lap_offset[k] in abs_lap
uniform ivec2 lap_size_wh[MAX_LAPLACIAN_LEVEL + 1];   // level k on G_{k-1}'s grid
uniform ivec2 headroom_size_wh;
uniform int headroom_block;
layout(std430, binding = B_ABSLAP) readonly buffer AbsLap { float abs_lap[]; };
layout(std430, binding = B_HEADROOM) readonly buffer Headroom { float headroom[]; };  // lo, hi

// amplitude.laplacian_level (eq. 8): the continuous level whose centre 2^-(l + 0.5) the blur
// attenuates to `attenuation`, at least 1; sigma 0 gives level 1
float laplacian_level(float sigma_px) {
    if (!(sigma_px > 0.0)) return 1.0;
    float f_c = sqrt(-2.0 * log(attenuation)) / (2.0 * PI * sigma_px);
    return max(log2(1.0 / f_c) - 0.5, 1.0);
}

float abs_laplacian_sample(int k, vec2 p_px) {
    ivec4 idx;
    vec4 wts;
    bilinear_taps(p_px / float(1 << (k - 1)), lap_size_wh[k], idx, wts);
    int o = lap_offset[k];
    return wts.x * abs_lap[o + idx.x] + wts.y * abs_lap[o + idx.y]
         + wts.z * abs_lap[o + idx.z] + wts.w * abs_lap[o + idx.w];
}

// amplitude.laplacian_amplitude_at: |L| at a continuous level, linear between the two
// bracketing levels (the level index is log2 of frequency: the log domain of eq. 9)
float laplacian_amplitude_at(float level, vec2 p_px) {
    level = min(level, float(lap_top));
    int k0 = lap_top > 1 ? min(int(floor(level)), lap_top - 1) : 1;
    float t = clamp(level - float(k0), 0.0, 1.0);
    float lo = abs_laplacian_sample(k0, p_px);
    float hi = k0 + 1 <= lap_top ? abs_laplacian_sample(k0 + 1, p_px) : lo;
    return (1.0 - t) * lo + t * hi;
}

// amplitude.headroom_limit at the block holding p: the largest K with N_max + K/2 <= 1 and
// N_min - K/2 >= 0, never negative (section 4.2)
float headroom_limit_at(vec2 p_px) {
    int i = nearest_index(p_px, headroom_block, headroom_size_wh);
    int n = headroom_size_wh.x * headroom_size_wh.y;
    return max(2.0 * min(1.0 - headroom[n + i], headroom[i]), 0.0);
}

// eq. 9 with the release's gain, then the clipping control
float amplitude_k(float s_k, float laplacian_amplitude, float limit) {
    return min(s_k * RELEASE_AMPLITUDE_GAIN * laplacian_amplitude, limit);
}
