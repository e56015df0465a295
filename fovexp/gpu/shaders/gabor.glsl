// Sparse Gabor noise: fovexp/gabor.py (Lagae et al. 2009; paper section 4.4; docs/METHOD.md, 4, 5.9).
// n(x) = sum_i A_i exp(-pi a^2 |d|^2) cos(k_i . d), d = x - x_i, over the impulses whose
// kernel square |d_x|, |d_y| <= r reaches x; A_i = w_i K_i / (6 sqrt(V)) and the carrier
// wave vector k_i = 2 pi F_i (cos t_i, sin t_i) come from the per-impulse stage. Each pixel
// gathers from the 3 x 3 cells (side r) around it; impulses with A_i = 0 cost a read.
// Skipping (EngineOptions.skip): a work group none of whose cells holds an impulse with A_i != 0
// (an empty band, a flat surround: gabor.synthesize leaves those out) writes 0 at once, what
// its sums give.

#ifdef ENTRY_NOISE
LOCAL_2D
uniform ivec2 image_hw;
uniform float gabor_a_cpp;
uniform float kernel_radius_px;
uniform float cell_px;
uniform ivec2 cell_count_xy;    // gabor.cell_counts: cells from -CELL_BORDER, row by row
uniform int skip;
layout(std430, binding = B_IMPULSES) readonly buffer Impulses { vec4 impulses[]; };  // x, y, w, -
layout(std430, binding = B_CELLS) readonly buffer Cells { int cell_start[]; };
layout(std430, binding = B_IMP_PARAMS) readonly buffer Params { float imp_params[]; };
layout(std430, binding = B_NOISE) writeonly buffer Noise { float noise[]; };
shared uint group_live;

// gabor.cell_index of a pixel
ivec2 cell_of(vec2 q) { return ivec2(floor((q - CELL_ORIGIN_PX) / cell_px)) + CELL_BORDER; }

// whether any impulse the group's pixels gather from has a non-zero amplitude; the group's
// invocations share the impulses to look at (a uniform result)
bool group_live_any() {
    if (gl_LocalInvocationIndex == 0u) group_live = 0u;
    barrier();
    vec2 g0 = vec2(ivec2(gl_WorkGroupID.xy) * GROUP_2D);
    ivec2 c0 = max(cell_of(g0) - 1, 0);
    ivec2 c1 = min(cell_of(g0 + vec2(GROUP_2D) - 1.0) + 1, cell_count_xy - 1);
    int nx = c1.x - c0.x + 1;
    // impulses of the cells row by row of cells: each row of cells is one run of records
    for (int cy = c0.y; cy <= c1.y; ++cy) {
        int first = cell_start[cy * cell_count_xy.x + c0.x];
        int last = cell_start[cy * cell_count_xy.x + c0.x + nx];
        for (int i = first + int(gl_LocalInvocationIndex); i < last; i += LOCAL_2D_SIZE)
            if (imp_params[i * IMP_STRIDE + IMP_AMP] != 0.0) atomicOr(group_live, 1u);
    }
    barrier();
    return group_live != 0u;
}

void main() {
    bool live = skip == 0 || group_live_any();
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= image_hw.y || p.y >= image_hw.x) return;
    if (!live) { noise[p.y * image_hw.y + p.x] = 0.0; return; }
    vec2 q = vec2(p);
    ivec2 c = cell_of(q);
    float pa2 = PI * gabor_a_cpp * gabor_a_cpp;
    float r = kernel_radius_px;
    float acc = 0.0;
    for (int cy = max(c.y - 1, 0); cy <= min(c.y + 1, cell_count_xy.y - 1); ++cy) {
        for (int cx = max(c.x - 1, 0); cx <= min(c.x + 1, cell_count_xy.x - 1); ++cx) {
            int cell = cy * cell_count_xy.x + cx;
            for (int i = cell_start[cell]; i < cell_start[cell + 1]; ++i) {
                float amp = imp_params[i * IMP_STRIDE + IMP_AMP];
                if (amp == 0.0) continue;
                vec2 d = q - impulses[i].xy;
                if (abs(d.x) > r || abs(d.y) > r) continue;
                float phase = imp_params[i * IMP_STRIDE + IMP_KX] * d.x + imp_params[i * IMP_STRIDE + IMP_KY] * d.y;
                acc += amp * exp(-pa2 * dot(d, d)) * cos(phase);
            }
        }
    }
    noise[p.y * image_hw.y + p.x] = acc;
}
#endif
