// Image pyramids: fovexp/pyramids.py (paper sections 4.2, 4.3; notes sections 3.5, 3.7, 3.8).
// Levels of one pyramid are packed in one buffer at offsets the backend keeps; sample j of
// level m sits on full-resolution pixel j * 2^m.

// pyramids.sample_bilinear: the four taps of a bilinear sample at level coordinates uv of a
// w x h grid, borders held (scipy map_coordinates, order 1, mode "nearest")
void bilinear_taps(vec2 uv, ivec2 size_wh, out ivec4 idx, out vec4 wts) {
    vec2 f = floor(uv);
    vec2 a = uv - f;
    ivec2 lo = clamp(ivec2(f), ivec2(0), size_wh - 1);
    ivec2 hi = clamp(ivec2(f) + 1, ivec2(0), size_wh - 1);
    idx = ivec4(lo.y * size_wh.x + lo.x, lo.y * size_wh.x + hi.x,
                hi.y * size_wh.x + lo.x, hi.y * size_wh.x + hi.x);
    wts = vec4((1.0 - a.x) * (1.0 - a.y), a.x * (1.0 - a.y), (1.0 - a.x) * a.y, a.x * a.y);
}

// pyramids.sample_nearest: the block x block cell of a w x h grid that holds pixel p
int nearest_index(vec2 p_px, int block, ivec2 size_wh) {
    ivec2 q = clamp(ivec2(max(p_px, 0.0) + 0.5) / block, ivec2(0), size_wh - 1);
    return q.y * size_wh.x + q.x;
}

#ifdef ENTRY_REDUCE
// pyramids.reduce: 5-tap binomial filter, replicated borders, every second sample. The source
// may carry a virtual replicated border of src_pad px (level 0 of the foveation pyramid).
LOCAL_2D
uniform ivec3 src_hwc;
uniform int src_offset;
uniform int src_pad;
uniform ivec2 dst_hw;
uniform int dst_offset;
layout(std430, binding = B_REDUCE_SRC) readonly buffer Src { float src[]; };
layout(std430, binding = B_REDUCE_DST) writeonly buffer Dst { float dst[]; };
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= dst_hw.y || p.y >= dst_hw.x) return;
    int h = src_hwc.x, w = src_hwc.y, c = src_hwc.z;
    int hv = h + 2 * src_pad, wv = w + 2 * src_pad;
    for (int ch = 0; ch < c; ++ch) {
        float acc = 0.0;
        for (int dx = -2; dx <= 2; ++dx) {
            int x = clamp(clamp(2 * p.x + dx, 0, wv - 1) - src_pad, 0, w - 1);
            float col = 0.0;
            for (int dy = -2; dy <= 2; ++dy) {
                int y = clamp(clamp(2 * p.y + dy, 0, hv - 1) - src_pad, 0, h - 1);
                col += BINOMIAL_5[dy + 2] * src[src_offset + (y * w + x) * c + ch];
            }
            acc += BINOMIAL_5[dx + 2] * col;
        }
        dst[dst_offset + (p.y * dst_hw.y + p.x) * c + ch] = acc;
    }
}
#endif

#ifdef ENTRY_ABS_LAPLACIAN
// |L_k| = |G_{k-1} - expand(G_k)| (pyramids.expand's polyphase taps, borders replicated);
// the 3 x 3 mean of the next entry smooths it (pyramids.smoothed_abs_laplacian)
LOCAL_2D
uniform ivec2 fine_hw;
uniform int fine_offset;
uniform ivec2 coarse_hw;
uniform int coarse_offset;
layout(std430, binding = B_LUMA_PYR) readonly buffer Pyr { float pyr[]; };
layout(std430, binding = B_LAP_TMP) writeonly buffer Tmp { float tmp[]; };
void expand_taps(int y, int n, out ivec3 idx, out vec3 wts) {
    int i = y / 2;
    if (y % 2 == 0) {
        idx = ivec3(max(i - 1, 0), i, min(i + 1, n - 1));
        wts = EXPAND_EVEN_TAPS;
    } else {
        idx = ivec3(i, min(i + 1, n - 1), i);
        wts = vec3(EXPAND_ODD_TAPS, 0.0);
    }
}
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= fine_hw.y || p.y >= fine_hw.x) return;
    ivec3 iy, ix;
    vec3 wy, wx;
    expand_taps(p.y, coarse_hw.x, iy, wy);
    expand_taps(p.x, coarse_hw.y, ix, wx);
    float up = 0.0;
    for (int b = 0; b < 3; ++b) {
        float row = 0.0;
        for (int a = 0; a < 3; ++a) row += wy[a] * pyr[coarse_offset + iy[a] * coarse_hw.y + ix[b]];
        up += wx[b] * row;
    }
    tmp[p.y * fine_hw.y + p.x] = abs(pyr[fine_offset + p.y * fine_hw.y + p.x] - up);
}
#endif

#ifdef ENTRY_BOX3
// 3 x 3 mean, borders replicated (notes 3.7): the smoothed |L_k| on G_{k-1}'s grid
LOCAL_2D
uniform ivec2 grid_hw;
uniform int dst_offset;
layout(std430, binding = B_LAP_TMP) readonly buffer Tmp { float tmp[]; };
layout(std430, binding = B_ABSLAP) writeonly buffer AbsLap { float abs_lap[]; };
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    int h = grid_hw.x, w = grid_hw.y;
    if (p.x >= w || p.y >= h) return;
    float acc = 0.0;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
            acc += tmp[clamp(p.y + dy, 0, h - 1) * w + clamp(p.x + dx, 0, w - 1)];
    abs_lap[dst_offset + p.y * w + p.x] = acc / 9.0;
}
#endif

#ifdef ENTRY_BLOCK_EXTREMES
// pyramids.block_extremes: min and max of each block x block block of the image the noise is
// added to (foveated + contrast change), over every channel (paper section 4.2)
LOCAL_2D
uniform ivec3 image_hwc;
uniform int block;
uniform ivec2 grid_hw;
layout(std430, binding = B_FOVEATED) readonly buffer Foveated { float foveated[]; };
layout(std430, binding = B_CONTRAST) readonly buffer Contrast { float delta[]; };
layout(std430, binding = B_EXTREMES) writeonly buffer Extremes { float extremes[]; };
void main() {
    ivec2 b = ivec2(gl_GlobalInvocationID.xy);
    if (b.x >= grid_hw.y || b.y >= grid_hw.x) return;
    int h = image_hwc.x, w = image_hwc.y, c = image_hwc.z;
    float lo = 3.0e38, hi = -3.0e38;
    for (int y = b.y * block; y < min(b.y * block + block, h); ++y) {
        for (int x = b.x * block; x < min(b.x * block + block, w); ++x) {
            int i = y * w + x;
            for (int ch = 0; ch < c; ++ch) {
                float v = foveated[i * c + ch] + delta[i];
                lo = min(lo, v);
                hi = max(hi, v);
            }
        }
    }
    int n = grid_hw.x * grid_hw.y;
    extremes[b.y * grid_hw.y + b.x] = lo;
    extremes[n + b.y * grid_hw.y + b.x] = hi;
}
#endif

#ifdef ENTRY_EXTREMES_FILTER
// widen the blocks to every block a kernel reaches: minimum and maximum filters of odd size
// 2 radius + 1 on the block grid, borders replicated (scipy.ndimage, mode "nearest")
LOCAL_2D
uniform ivec2 grid_hw;
uniform int radius;
layout(std430, binding = B_EXTREMES) readonly buffer Extremes { float extremes[]; };
layout(std430, binding = B_HEADROOM) writeonly buffer Headroom { float headroom[]; };
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    int h = grid_hw.x, w = grid_hw.y, n = h * w;
    if (p.x >= w || p.y >= h) return;
    float lo = 3.0e38, hi = -3.0e38;
    for (int dy = -radius; dy <= radius; ++dy) {
        for (int dx = -radius; dx <= radius; ++dx) {
            int i = clamp(p.y + dy, 0, h - 1) * w + clamp(p.x + dx, 0, w - 1);
            lo = min(lo, extremes[i]);
            hi = max(hi, extremes[n + i]);
        }
    }
    headroom[p.y * w + p.x] = lo;
    headroom[n + p.y * w + p.x] = hi;
}
#endif
