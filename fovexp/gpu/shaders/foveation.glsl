// Foveation: fovexp/foveation.py. The sigma map (paper section 5.2) and the fast blur stack:
// Gaussian blurs at fixed sigmas, each on the pyramid level its plan names (the plan is
// foveation.blur_stack_plan, computed once in Python for both backends), and per pixel the
// linear interpolation between the two stack levels that bracket its sigma, as the pixel's
// own value plus the weighted differences of the levels from it, and the blurs as "centre +
// weighted differences" (the CPU's arithmetic): a constant region comes out as its constant,
// so the flat tiles skipping leaves alone are exactly those the blur would leave unchanged.

#include "geometry.glsl"
#include "pyramids.glsl"

uniform float blur_rate_arcmin_per_deg;
uniform float fovea_deg;

// foveation.sigma_px: blur_rate * max(0, e - fovea) arcmin, in px (geometry.arcmin_to_px)
float sigma_px(float ecc_deg, float ppd) {
    return max(ecc_deg - fovea_deg, 0.0) * blur_rate_arcmin_per_deg / ARCMIN_PER_DEG * ppd;
}

#ifdef ENTRY_SIGMA
// sigma per pixel from the geometry, and each tile's range (the stack levels it needs); the
// blur stack's extent is the CPU's bound of the map (foveation.sigma_bound_px)
LOCAL_2D
uniform ivec2 size_wh;
layout(std430, binding = B_SIGMA) writeonly buffer Sigma { float sigma[]; };
layout(std430, binding = B_TILES) writeonly buffer Tiles { vec2 tiles[]; };
shared uint group_min_bits, group_max_bits;
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (gl_LocalInvocationIndex == 0u) { group_min_bits = 0x7F800000u; group_max_bits = 0u; }
    barrier();
    if (all(lessThan(p, size_wh))) {
        float s = sigma_px(eccentricity_deg(vec2(p)), ppd(vec2(p)));
        sigma[p.y * size_wh.x + p.x] = s;
        // non-negative floats order as their bit patterns
        atomicMin(group_min_bits, floatBitsToUint(s));
        atomicMax(group_max_bits, floatBitsToUint(s));
    }
    barrier();
    if (gl_LocalInvocationIndex == 0u) {  // the tile's sigma range
        tiles[gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x] =
            vec2(uintBitsToFloat(group_min_bits), uintBitsToFloat(group_max_bits));
    }
}
#endif

#if defined(ENTRY_BLUR) || defined(ENTRY_STACK_ACCUMULATE)
// Work a stack level does not need is skipped by whole work groups: the sigma pass records
// each TILE_PX x TILE_PX tile's sigma range, and a pixel uses stack level l only if its sigma
// lies in (need_lo, need_hi] = (sigma_{l-1}, sigma_{l+1}] (the CPU backend skips the same
// pixels by runs of columns); no pixel of a tile STACK_INIT found flat uses any level.
uniform float need_lo;
uniform float need_hi;
uniform ivec2 tile_grid_wh;
layout(std430, binding = B_TILES) readonly buffer Tiles { vec2 tiles[]; };
layout(std430, binding = B_FLAT_FLAGS) readonly buffer FlatFlags { uint flat_flags[]; };
shared uint group_needed;

bool tile_needed(ivec2 t) {
    int i = t.y * tile_grid_wh.x + t.x;
    vec2 r = tiles[i];
    return flat_flags[i] == 0u && r.y > need_lo && r.x <= need_hi;
}

// whether any tile meeting the full-resolution rectangle [lo_px, hi_px] needs this level;
// the group's invocations share the tiles to look at (uniform result: call from all of them)
bool region_needed(ivec2 lo_px, ivec2 hi_px) {
    if (gl_LocalInvocationIndex == 0u) group_needed = 0u;
    barrier();
    ivec2 t0 = clamp(max(lo_px, 0) / TILE_PX, ivec2(0), tile_grid_wh - 1);
    ivec2 t1 = clamp(max(hi_px, 0) / TILE_PX, ivec2(0), tile_grid_wh - 1);
    int nx = t1.x - t0.x + 1, n = nx * (t1.y - t0.y + 1);
    // (it stops once one was found: pyramids.glsl's region_constant says why)
    for (int t = int(gl_LocalInvocationIndex); t < n && group_needed == 0u; t += LOCAL_2D_SIZE)
        if (tile_needed(t0 + ivec2(t % nx, t / nx))) atomicOr(group_needed, 1u);
    barrier();
    return group_needed != 0u;
}
#endif

#ifdef ENTRY_BLUR
// one pass of a separable Gaussian (foveation._blur_patch): along y, then a second dispatch
// along x; samples outside the grid replicate its border; the centre plus the weighted
// differences from it, the symmetric taps in pairs: (a + b) - 2 centre (foveation._blur_patch)
LOCAL_2D
uniform ivec3 grid_hwc;
uniform int src_offset;
uniform int kernel_offset;
uniform int kernel_radius;
uniform int along_y;
uniform int level_scale;      // full-resolution px per level sample
uniform int level_pad_px;     // the level grid's replicated border, full-resolution px
layout(std430, binding = B_BLUR_SRC) readonly buffer Src { float src[]; };
layout(std430, binding = B_BLUR_DST) writeonly buffer Dst { float dst[]; };
layout(std430, binding = B_KERNELS) readonly buffer Kernels { float kernels[]; };
void main() {
    // the full-resolution pixels that read this group's samples (bilinearly: one sample
    // either side), and, after the pass along y, those the pass along x reads (kernel_radius)
    ivec2 g0 = ivec2(gl_WorkGroupID.xy) * ivec2(gl_WorkGroupSize.xy);
    ivec2 margin = ivec2(along_y == 1 ? kernel_radius + 1 : 1, 1);
    if (!region_needed((g0 - margin) * level_scale - level_pad_px,
                       (g0 + ivec2(gl_WorkGroupSize.xy) + margin) * level_scale - level_pad_px))
        return;
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    int h = grid_hwc.x, w = grid_hwc.y, c = grid_hwc.z;
    if (p.x >= w || p.y >= h) return;
    for (int ch = 0; ch < c; ++ch) {
        float centre = src[src_offset + (p.y * w + p.x) * c + ch];
        float twice = centre + centre;
        float acc = centre;
        // the kernel is symmetric: taps -k and +k in pairs, outermost first (as the CPU)
        for (int k = -kernel_radius; k < 0; ++k) {
            ivec2 a = along_y == 1 ? ivec2(p.x, clamp(p.y + k, 0, h - 1))
                                   : ivec2(clamp(p.x + k, 0, w - 1), p.y);
            ivec2 b = along_y == 1 ? ivec2(p.x, clamp(p.y - k, 0, h - 1))
                                   : ivec2(clamp(p.x - k, 0, w - 1), p.y);
            acc += kernels[kernel_offset + k + kernel_radius]
                 * ((src[src_offset + (a.y * w + a.x) * c + ch]
                     + src[src_offset + (b.y * w + b.x) * c + ch]) - twice);
        }
        dst[(p.y * w + p.x) * c + ch] = acc;
    }
}
#endif

#ifdef ENTRY_STACK_INIT
// each pixel's bracketing stack levels (k, t), and the pixel's own value (level 0, the image
// itself, adds nothing more). Skipping: a group whose tile and reach_px around it are one
// constant in every channel leaves its pixels as they are (what the blur gives there) and
// flags its tile, so that no stack level blurs or accumulates for it.
LOCAL_2D
uniform ivec3 image_hwc;
uniform int n_levels;
uniform int reach_px;             // foveation.BlurStackPlan.reach_px
layout(std430, binding = B_LINEAR) readonly buffer Linear { float linear[]; };
layout(std430, binding = B_SIGMA) readonly buffer Sigma { float sigma[]; };
layout(std430, binding = B_LEVELS) readonly buffer Levels { float levels[]; };
layout(std430, binding = B_BRACKET) writeonly buffer Bracket { vec2 bracket[]; };
layout(std430, binding = B_FOVEATED) writeonly buffer Foveated { float foveated[]; };
layout(std430, binding = B_FLAT_FLAGS) writeonly buffer FlatFlags { uint flat_flags[]; };
void main() {
    ivec2 g0 = ivec2(gl_WorkGroupID.xy) * GROUP_2D;
    bool is_flat = skip == 1 && region_constant(g0 - reach_px, g0 + GROUP_2D - 1 + reach_px);
    if (gl_LocalInvocationIndex == 0u)
        flat_flags[gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x] = is_flat ? 1u : 0u;
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    int h = image_hwc.x, w = image_hwc.y, c = image_hwc.z;
    if (p.x >= w || p.y >= h) return;
    int i = p.y * w + p.x;
    float s = sigma[i];
    for (int ch = 0; ch < c; ++ch) foveated[i * c + ch] = linear[i * c + ch];
    if (s <= 0.0 || is_flat) {  // untouched, bit for bit
        bracket[i] = vec2(-1.0, 0.0);
        return;
    }
    int k = -1;  // numpy.searchsorted(levels, s) - 1
    for (int j = 0; j < n_levels; ++j) k += levels[j] < s ? 1 : 0;
    k = min(k, n_levels - 2);
    float t = min((s - levels[k]) / (levels[k + 1] - levels[k]), 1.0);
    bracket[i] = vec2(float(k), t);
}
#endif

#ifdef ENTRY_STACK_ACCUMULATE
// add stack level `stack_level` (blurred on a pyramid level, sampled bilinearly), less the
// pixel's own value, weighted, to the pixels whose sigma it brackets
LOCAL_2D
uniform ivec3 image_hwc;
uniform int stack_level;
uniform int level_scale;
uniform int level_pad_px;
uniform ivec2 level_hw;
layout(std430, binding = B_BLUR_DST) readonly buffer Blurred { float blurred[]; };
layout(std430, binding = B_BRACKET) readonly buffer Bracket { vec2 bracket[]; };
layout(std430, binding = B_FOVEATED) buffer Foveated { float foveated[]; };
layout(std430, binding = B_LINEAR) readonly buffer Linear { float linear[]; };
void main() {
    if (!tile_needed(ivec2(gl_WorkGroupID.xy))) return;  // the group is one tile
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    int h = image_hwc.x, w = image_hwc.y, c = image_hwc.z;
    if (p.x >= w || p.y >= h) return;
    int i = p.y * w + p.x;
    vec2 kt = bracket[i];
    int k = int(kt.x);
    float wgt;
    if (k == stack_level) wgt = 1.0 - kt.y;
    else if (k == stack_level - 1) wgt = kt.y;
    else return;
    vec2 f = vec2(p + level_pad_px) / float(level_scale);
    ivec2 i0 = ivec2(f);
    vec2 a = f - vec2(i0);
    ivec2 i1 = min(i0 + 1, ivec2(level_hw.y, level_hw.x) - 1);
    int lw = level_hw.y;
    // the bilinear sample as foveation._accumulate computes it: along x, then between the
    // two rows, each step a + f (b - a) (a constant level gives exactly its constant)
    for (int ch = 0; ch < c; ++ch) {
        float v = linear[i * c + ch];
        float p00 = blurred[(i0.y * lw + i0.x) * c + ch];
        float p10 = blurred[(i1.y * lw + i0.x) * c + ch];
        float u0 = p00 + a.x * (blurred[(i0.y * lw + i1.x) * c + ch] - p00);
        float u1 = p10 + a.x * (blurred[(i1.y * lw + i1.x) * c + ch] - p10);
        foveated[i * c + ch] += wgt * ((u0 + a.y * (u1 - u0)) - v);
    }
}
#endif
