// Noise orientation: fovexp/orientation.py (paper section 4.3; docs/METHOD.md, 5.5). Sobel
// gradients on Gaussian level ORIENTATION_LEVEL, brought to full-resolution points by Keys
// cubic convolution (a = KEYS_A: MATLAB's imresize 'bicubic'); omega = atan2(G_y, G_x) - pi/2.

#ifdef ENTRY_SOBEL
// orientation.sobel_gradients: G_x then G_y, replicated borders
LOCAL_2D
uniform ivec2 level_hw;
uniform int level_offset;
layout(std430, binding = B_LUMA_PYR) readonly buffer Pyr { float pyr[]; };
layout(std430, binding = B_GRADIENTS) writeonly buffer Gradients { float gradients[]; };
float at(int x, int y) {
    return pyr[level_offset + clamp(y, 0, level_hw.x - 1) * level_hw.y + clamp(x, 0, level_hw.y - 1)];
}
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= level_hw.y || p.y >= level_hw.x) return;
    float gx = 0.0, gy = 0.0;
    for (int d = -1; d <= 1; ++d) {
        float s = d == 0 ? 2.0 : 1.0;
        gx += s * (at(p.x + 1, p.y + d) - at(p.x - 1, p.y + d));
        gy += s * (at(p.x + d, p.y + 1) - at(p.x + d, p.y - 1));
    }
    int i = p.y * level_hw.y + p.x;
    gradients[i] = gx;
    gradients[level_hw.x * level_hw.y + i] = gy;
}
#else
uniform ivec2 gradient_size_wh;
layout(std430, binding = B_GRADIENTS) readonly buffer Gradients { float gradients[]; };

// pyramids._keys_weight: Keys' cubic-convolution kernel
float keys_weight(float t) {
    t = abs(t);
    if (t <= 1.0) return ((KEYS_A + 2.0) * t - (KEYS_A + 3.0)) * t * t + 1.0;
    if (t < 2.0) return ((KEYS_A * t - 5.0 * KEYS_A) * t + 8.0 * KEYS_A) * t - 4.0 * KEYS_A;
    return 0.0;
}

// pyramids.sample_cubic of G_x (component 0) or G_y (1) at a full-resolution point
float gradient_cubic(int component, vec2 p_px) {
    vec2 uv = p_px / float(1 << ORIENTATION_LEVEL);
    vec2 f = floor(uv);
    vec2 a = uv - f;
    ivec2 i0 = ivec2(f);
    int w = gradient_size_wh.x, h = gradient_size_wh.y;
    int base = component * w * h;
    float acc = 0.0;
    for (int j = 0; j < 4; ++j) {
        float wy = keys_weight(a.y + 1.0 - float(j));
        int y = clamp(i0.y - 1 + j, 0, h - 1);
        for (int k = 0; k < 4; ++k)
            acc += wy * keys_weight(a.x + 1.0 - float(k)) * gradients[base + y * w + clamp(i0.x - 1 + k, 0, w - 1)];
    }
    return acc;
}

// orientation.orientation_at: omega in rad; -pi/2 where |G| < GRADIENT_EPS (a flat area)
float orientation_at(vec2 p_px) {
    float gx = gradient_cubic(0, p_px), gy = gradient_cubic(1, p_px);
    return (length(vec2(gx, gy)) < GRADIENT_EPS ? 0.0 : atan(gy, gx)) - 0.5 * PI;
}
#endif
