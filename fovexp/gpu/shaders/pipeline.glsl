// The per-impulse stages of fovexp/pipeline.py composed: at each impulse (or, for the maps,
// each pixel) the band (section 4.1), the frequency draw, the amplitude with its clipping
// control (4.2) and the orientation (4.3); the Gabor synthesis (gabor.glsl) reads the result.

#include "geometry.glsl"
#include "acuity.glsl"
#include "foveation.glsl"
#include "pyramids.glsl"
#include "frequency.glsl"
#include "amplitude.glsl"
#include "orientation.glsl"

uniform ivec2 image_wh;
uniform int sigma_from_map;       // 1: an already-foveated frame with a given sigma map
uniform float s_f;
uniform float s_k;
uniform float noise_norm;         // gabor.normalisation: 1 / (6 sqrt(V))
layout(std430, binding = B_SIGMA) readonly buffer Sigma { float sigma_map[]; };

// Enhancer._band_at: sigma from the geometry, or sampled bilinearly from the given map
float sigma_at(vec2 p_px) {
    if (sigma_from_map == 0) return sigma_px(eccentricity_deg(p_px), ppd(p_px));
    ivec4 idx;
    vec4 wts;
    bilinear_taps(p_px, image_wh, idx, wts);
    return wts.x * sigma_map[idx.x] + wts.y * sigma_map[idx.y] + wts.z * sigma_map[idx.z] + wts.w * sigma_map[idx.w];
}

// (F_L, F_H) at a point, the point held inside the image (Enhancer._imp_band); sigma out
vec2 band_at(vec2 p_px, out float sigma, out float ecc) {
    vec2 pc = clamp(p_px, vec2(0.0), vec2(image_wh - 1));
    ecc = eccentricity_deg(pc);
    float d = ppd(pc);
    sigma = sigma_at(pc);
    return frequency_band_cpp(ecc, d, sigma);
}

#ifdef ENTRY_IMPULSES
LOCAL_1D
uniform int n_impulses;
uniform int first_impulse;        // this dispatch's first (a dispatch has at most the driver's groups)
layout(std430, binding = B_IMPULSES) readonly buffer Impulses { vec4 impulses[]; };    // x, y, w, -
layout(std430, binding = B_QUANTILES) readonly buffer Quantiles { vec2 quantiles[]; }; // u, 1 - u
layout(std430, binding = B_IMP_PARAMS) writeonly buffer Params { float imp_params[]; };
void main() {
    int i = first_impulse + int(gl_GlobalInvocationID.x);
    if (i >= n_impulses) return;
    vec2 p = impulses[i].xy;
    float s, ecc;
    vec2 band = band_at(p, s, ecc);
    float amp = 0.0, kx = 0.0, ky = 0.0, k = 0.0, f = 0.0, omega = 0.0;
    if (band.x < band.y) {  // an open band: the impulse contributes
        f = draw_truncated(quantiles[i].x, quantiles[i].y, lognormal_params(band, s_f), band.y);
        k = amplitude_k(s_k, laplacian_amplitude_at(laplacian_level(s), p), headroom_limit_at(p));
        omega = orientation_at(p);
        float t = omega - 0.5 * PI;  // the carrier runs along the gradient
        amp = impulses[i].z * k * noise_norm;
        kx = 2.0 * PI * f * cos(t);
        ky = 2.0 * PI * f * sin(t);
    }
    int o = i * IMP_STRIDE;
    imp_params[o + IMP_AMP] = amp;
    imp_params[o + IMP_KX] = kx;
    imp_params[o + IMP_KY] = ky;
    imp_params[o + IMP_K] = k;
    imp_params[o + IMP_F] = f;
    imp_params[o + IMP_OMEGA] = omega;
    imp_params[o + IMP_F_LOW] = band.x;
    imp_params[o + IMP_F_HIGH] = band.y;
}
#endif

#ifdef ENTRY_MAPS
// one of the same functions on the pixel grid (Enhancer._read_map), the map map_field of
// pipeline.POINT_MAPS: eccentricity, F_L, F_H, K (0 where the band is closed), omega. One
// map per dispatch: the buffer bound holds one map, and only the map asked for is computed.
LOCAL_2D
uniform int map_field;
layout(std430, binding = B_MAP) writeonly buffer Map { float map_values[]; };
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= image_wh.x || p.y >= image_wh.y) return;
    vec2 q = vec2(p);
    float v;
    if (map_field == MAP_ORIENTATION_RAD) {
        v = orientation_at(q);
    } else {
        float s, ecc;
        vec2 band = band_at(q, s, ecc);
        if (map_field == MAP_ECCENTRICITY_DEG) v = ecc;
        else if (map_field == MAP_F_LOW_CPP) v = band.x;
        else if (map_field == MAP_F_HIGH_CPP) v = band.y;
        else v = band.x < band.y  // MAP_AMPLITUDE
            ? amplitude_k(s_k, laplacian_amplitude_at(laplacian_level(s), q), headroom_limit_at(q)) : 0.0;
    }
    map_values[p.y * image_wh.x + p.x] = v;
}
#endif
