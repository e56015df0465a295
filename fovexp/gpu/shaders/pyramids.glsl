// Image pyramids: fovexp/pyramids.py (paper sections 4.2, 4.3; docs/METHOD.md, 5.5, 5.7, 5.8).
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

// pyramids._taps5 / _taps3 / _taps2: the binomial filters as "centre + weighted differences",
// in the CPU's order of operations, so that a constant region gives exactly its constant
float taps5(float c, float m2, float m1, float p1, float p2) {
    return c + (BINOMIAL_5[0] * ((m2 - c) + (p2 - c)) + BINOMIAL_5[1] * ((m1 - c) + (p1 - c)));
}
float taps3(float c, float m1, float p1) { return c + EXPAND_EVEN_TAPS[0] * ((m1 - c) + (p1 - c)); }
float taps2(float c, float p1) { return c + EXPAND_ODD_TAPS[0] * (p1 - c); }

#if defined(ENTRY_ABS_LAPLACIAN) || defined(ENTRY_BOX3) || defined(ENTRY_CONTRAST_CHANGE) \
    || defined(ENTRY_STACK_INIT)
// Skipping (EngineOptions.skip): a work group whose results depend only on a region where the
// image is one constant (in every channel) writes what its arithmetic gives there (0 for |L|
// and the contrast change, the input for the foveation: pyramids.constant_blocks on the CPU).
// The image's TILE_PX x TILE_PX tile extremes (TILE_EXTREMES) tell; the group's invocations
// share the tiles to look at.
uniform int skip;
uniform ivec3 flat_tiles_hwc;     // tiles per column, per row, channels
layout(std430, binding = B_FLAT_TILES) readonly buffer FlatTiles { vec2 flat_tiles[]; };
shared uint group_varies;

// whether the image is one constant over the full-resolution rectangle [lo_px, hi_px]
// (clamped to the image) in each channel; a uniform result: call it from every invocation
bool region_constant(ivec2 lo_px, ivec2 hi_px) {
    if (gl_LocalInvocationIndex == 0u) group_varies = 0u;
    barrier();
    ivec2 wh = ivec2(flat_tiles_hwc.y, flat_tiles_hwc.x);
    int c = flat_tiles_hwc.z;
    ivec2 t0 = clamp(lo_px / TILE_PX, ivec2(0), wh - 1);
    ivec2 t1 = clamp(hi_px / TILE_PX, ivec2(0), wh - 1);
    int nx = t1.x - t0.x + 1, n = nx * (t1.y - t0.y + 1) * c;
    // a group stops looking once any of its invocations found a tile that differs: in a
    // textured region at once, where a wide reach would otherwise read thousands of tiles
    // (a stale read of the shared flag only looks further)
    for (int t = int(gl_LocalInvocationIndex); t < n && group_varies == 0u; t += LOCAL_2D_SIZE) {
        int ch = t % c, q = t / c;
        float ref = flat_tiles[(t0.y * wh.x + t0.x) * c + ch].x;
        vec2 e = flat_tiles[((t0.y + q / nx) * wh.x + t0.x + q % nx) * c + ch];
        if (e.x != ref || e.y != ref) atomicOr(group_varies, 1u);
    }
    barrier();
    return group_varies == 0u;
}

// whether this group's samples of a level-(k-1) grid (scale s = 2^(k-1)) read only a constant
// region: sample j depends on G_0 within s j +- 2 (s - 1), and reads samples j - margin ..
// j + margin of that grid (pyramids.abs_laplacian_reach_px)
bool group_flat(int level_scale, int margin) {
    if (skip == 0) return false;
    ivec2 g0 = ivec2(gl_WorkGroupID.xy) * GROUP_2D;
    ivec2 g1 = g0 + GROUP_2D - 1;
    int reach = 2 * (level_scale - 1);
    return region_constant((g0 - margin) * level_scale - reach, (g1 + margin) * level_scale + reach);
}
#endif

#ifdef ENTRY_TILE_EXTREMES
// min and max of each channel of an image (the luminance, the linear image, at most
// TILE_MAX_CHANNELS channels) over each TILE_PX x TILE_PX tile: every invocation loads its
// pixel, one per row and channel reduces the row, one per channel the rows (two barriers in
// all, where a halving tree took eight per channel: each barrier is a full stop of the
// group, and a software rasteriser pays for it in every group)
#define TILE_MAX_CHANNELS 4
LOCAL_2D
uniform ivec3 image_hwc;
layout(std430, binding = B_TILE_SRC) readonly buffer TileSrc { float tile_src[]; };
layout(std430, binding = B_FLAT_TILES) writeonly buffer FlatTiles { vec2 flat_tiles[]; };
shared float tile_px[TILE_MAX_CHANNELS * LOCAL_2D_SIZE];
shared vec2 tile_rows[TILE_MAX_CHANNELS * TILE_PX];
void main() {
    ivec2 p = min(ivec2(gl_GlobalInvocationID.xy), ivec2(image_hwc.y, image_hwc.x) - 1);
    uint i = gl_LocalInvocationIndex;
    ivec2 q = ivec2(gl_LocalInvocationID.xy);
    int c = image_hwc.z;
    for (int ch = 0; ch < c; ++ch)  // edge tiles repeat pixels
        tile_px[ch * LOCAL_2D_SIZE + int(i)] = tile_src[(p.y * image_hwc.y + p.x) * c + ch];
    barrier();
    if (q.x < c) {  // invocation (ch, y): channel ch of row y
        int row = q.x * LOCAL_2D_SIZE + q.y * TILE_PX;
        vec2 e = vec2(tile_px[row]);
        for (int x = 1; x < TILE_PX; ++x) {
            float v = tile_px[row + x];
            e = vec2(min(e.x, v), max(e.y, v));
        }
        tile_rows[q.x * TILE_PX + q.y] = e;
    }
    barrier();
    if (q.y == 0 && q.x < c) {  // invocation (ch, 0): channel ch of the tile
        vec2 e = tile_rows[q.x * TILE_PX];
        for (int y = 1; y < TILE_PX; ++y) {
            vec2 r = tile_rows[q.x * TILE_PX + y];
            e = vec2(min(e.x, r.x), max(e.y, r.y));
        }
        flat_tiles[(gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * c + q.x] = e;
    }
}
#endif

#ifdef ENTRY_REDUCE
// pyramids.reduce: 5-tap binomial filter, replicated borders, every second sample; down the
// columns first, then along the row (pyramids._reduce_hwc). The source may carry a virtual
// replicated border of src_pad px (level 0 of the foveation pyramid).
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
    int rows[5];
    for (int d = -2; d <= 2; ++d) rows[d + 2] = clamp(clamp(2 * p.y + d, 0, hv - 1) - src_pad, 0, h - 1);
    for (int ch = 0; ch < c; ++ch) {
        float col[5];
        for (int d = -2; d <= 2; ++d) {
            int x = clamp(clamp(2 * p.x + d, 0, wv - 1) - src_pad, 0, w - 1);
            int o = src_offset + x * c + ch;
            col[d + 2] = taps5(src[o + rows[2] * w * c], src[o + rows[0] * w * c],
                               src[o + rows[1] * w * c], src[o + rows[3] * w * c],
                               src[o + rows[4] * w * c]);
        }
        dst[dst_offset + (p.y * dst_hw.y + p.x) * c + ch] = taps5(col[2], col[0], col[1], col[3], col[4]);
    }
}
#endif

#ifdef ENTRY_ABS_LAPLACIAN
// |L_k| = |G_{k-1} - expand(G_k)| (pyramids._expand_row and _expand_at: down the columns,
// then along the row, borders replicated); the 3 x 3 mean of the next entry smooths it
// (pyramids.smoothed_abs_laplacian)
LOCAL_2D
uniform ivec2 fine_hw;
uniform int fine_offset;
uniform ivec2 coarse_hw;
uniform int coarse_offset;
uniform int level_scale;          // full-resolution px per sample of G_{k-1}
layout(std430, binding = B_LUMA_PYR) readonly buffer Pyr { float pyr[]; };
layout(std430, binding = B_LAP_TMP) writeonly buffer Tmp { float tmp[]; };
// the expansion down column `col` of the coarse grid at fine row y
float expand_column(int y, int col) {
    int i = y / 2, n = coarse_hw.x, cw = coarse_hw.y;
    float c = pyr[coarse_offset + i * cw + col];
    float p1 = pyr[coarse_offset + min(i + 1, n - 1) * cw + col];
    if (y % 2 == 1) return taps2(c, p1);
    return taps3(c, pyr[coarse_offset + max(i - 1, 0) * cw + col], p1);
}
void main() {
    // the expansion reads samples y - 5 .. y + 4 of G_{k-1}
    bool is_flat = group_flat(level_scale, 5);
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= fine_hw.y || p.y >= fine_hw.x) return;
    int i = p.y * fine_hw.y + p.x;
    if (is_flat) { tmp[i] = 0.0; return; }
    int j = p.x / 2, cw = coarse_hw.y;
    float c = expand_column(p.y, j), p1 = expand_column(p.y, min(j + 1, cw - 1));
    float up = p.x % 2 == 1 ? taps2(c, p1) : taps3(c, expand_column(p.y, max(j - 1, 0)), p1);
    tmp[i] = abs(pyr[fine_offset + i] - up);
}
#endif

#ifdef ENTRY_BOX3
// 3 x 3 mean, borders replicated (docs/METHOD.md, 5.7): the smoothed |L_k| on G_{k-1}'s grid
LOCAL_2D
uniform ivec2 grid_hw;
uniform int dst_offset;
uniform int level_scale;
layout(std430, binding = B_LAP_TMP) readonly buffer Tmp { float tmp[]; };
layout(std430, binding = B_ABSLAP) writeonly buffer AbsLap { float abs_lap[]; };
void main() {
    bool is_flat = group_flat(level_scale, 6);  // one sample more than ABS_LAPLACIAN's
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    int h = grid_hw.x, w = grid_hw.y;
    if (p.x >= w || p.y >= h) return;
    if (is_flat) { abs_lap[dst_offset + p.y * w + p.x] = 0.0; return; }
    float acc = 0.0;
    for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
            acc += tmp[clamp(p.y + dy, 0, h - 1) * w + clamp(p.x + dx, 0, w - 1)];
    abs_lap[dst_offset + p.y * w + p.x] = acc / 9.0;
}
#endif

#ifdef ENTRY_BLOCK_EXTREMES
// pyramids.block_extremes: min and max of each block x block block of the image the noise is
// added to (foveated + contrast change), over every channel, or of its luminance (luma + change)
// with over_luma (amplitude.clipping_extremes' "paper" rule; paper section 4.2)
LOCAL_2D
uniform ivec3 image_hwc;
uniform int block;
uniform ivec2 grid_hw;
uniform int over_luma;
layout(std430, binding = B_FOVEATED) readonly buffer Foveated { float foveated[]; };
layout(std430, binding = B_LUMA_PYR) readonly buffer Luma { float luma[]; };  // level 0 first
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
            if (over_luma != 0) {
                float v = luma[i] + delta[i];
                lo = min(lo, v);
                hi = max(hi, v);
                continue;
            }
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
