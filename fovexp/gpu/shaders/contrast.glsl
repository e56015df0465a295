// Contrast enhancement: fovexp/contrast.py (Patney et al. 2016 as the release applies it,
// docs/METHOD.md, 5.3). Per integer blur level k a box mean of width box_width_px(k) (MATLAB
// anchoring); the change out_k - in = (1 - f_e (1 + k)) (avg_k - in), and each pixel
// interpolates between the two levels that bracket its sigma. Box sums from an exact integer
// summed-area table of the luminance in fixed point (contrast.SAT_FRACTION_BITS; 64-bit
// integers, GL_ARB_gpu_shader_int64), padded with symmetric borders: the same numbers as the
// CPU's, whatever the order of the sums, and a flat box changes by exactly 0.

#include "pyramids.glsl"

// contrast._symmetric: MATLAB 'symmetric' padding (-1 -> 0, n -> n - 1), repeated past the
// edges (period 2n) when the pad is wider than the image; GLSL's % is undefined for i < 0
int symmetric(int i, int n) {
    int m = 2 * n;
    i -= m * int(floor(float(i) / float(m)));
    return i >= n ? m - 1 - i : i;
}

// contrast._fixed: v in the table's fixed point, round(v 2^SAT_FRACTION_BITS), ties to even
int64_t fixed_point(float v) {
    return int64_t(roundEven(double(v) * SAT_SCALE));
}

#ifdef ENTRY_SAT_ROWS
// contrast._sat, first pass: prefix sums along each padded row (one invocation per row)
LOCAL_1D
uniform ivec2 image_hw;
uniform int pad_px;
layout(std430, binding = B_LUMA_PYR) readonly buffer Luma { float luma[]; };  // level 0 first
layout(std430, binding = B_SAT) writeonly buffer Sat { int64_t sat[]; };
void main() {
    int y = int(gl_GlobalInvocationID.x);
    int h = image_hw.x, w = image_hw.y;
    int hp = h + 2 * pad_px, wp = w + 2 * pad_px;
    if (y >= hp) return;
    int sy = symmetric(y - pad_px, h);
    int row = (y + 1) * (wp + 1);
    int64_t run = 0l;
    sat[row] = 0l;
    for (int x = 0; x < wp; ++x) {
        run += fixed_point(luma[sy * w + symmetric(x - pad_px, w)]);
        sat[row + x + 1] = run;
    }
}
#endif

#ifdef ENTRY_SAT_COLS
// contrast._sat, second pass: prefix sums down each column (one invocation per column)
LOCAL_1D
uniform ivec2 image_hw;
uniform int pad_px;
layout(std430, binding = B_SAT) buffer Sat { int64_t sat[]; };
void main() {
    int x = int(gl_GlobalInvocationID.x) + 1;
    int hp = image_hw.x + 2 * pad_px, wp = image_hw.y + 2 * pad_px;
    if (x > wp) return;
    int64_t run = 0l;
    for (int y = 1; y <= hp; ++y) {
        run += sat[y * (wp + 1) + x];
        sat[y * (wp + 1) + x] = run;
    }
}
#endif

#ifdef ENTRY_CONTRAST_CHANGE
// contrast._change: the change of luminance the enhancement makes. Skipping
// (EngineOptions.skip): a work group whose pixels' boxes (pad_px around each) all lie where the
// luminance is one constant writes 0, exactly what its arithmetic gives there.
LOCAL_2D
uniform ivec2 image_hw;
uniform int pad_px;
uniform float f_e;
layout(std430, binding = B_LUMA_PYR) readonly buffer Luma { float luma[]; };
layout(std430, binding = B_SIGMA) readonly buffer Sigma { float sigma[]; };
layout(std430, binding = B_SAT) readonly buffer Sat { int64_t sat[]; };
layout(std430, binding = B_CONTRAST) writeonly buffer Contrast { float delta[]; };
void main() {
    // the group's pixels' boxes reach pad_px around its tile
    ivec2 g0 = ivec2(gl_WorkGroupID.xy) * GROUP_2D;
    bool is_flat = skip == 1 && region_constant(g0 - pad_px, g0 + GROUP_2D - 1 + pad_px);
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    int h = image_hw.x, w = image_hw.y;
    if (p.x >= w || p.y >= h) return;
    int i = p.y * w + p.x;
    float s = sigma[i];
    if (s <= 0.0 || is_flat) { delta[i] = 0.0; return; }
    int wp1 = w + 2 * pad_px + 1;
    int k0 = int(s);
    double t = double(s) - double(k0);
    int64_t qv = fixed_point(luma[i]);
    double acc = 0.0LF;
    for (int j = 0; j < 2; ++j) {
        int k = k0 + j;
        if (k == 0) continue;  // width 0: the pixel itself, no change
        double wgt = j == 0 ? 1.0LF - t : t;
        // width n = contrast.box_width_px(k), MATLAB anchoring:
        // [x - floor((n - 1) / 2), x + ceil((n - 1) / 2)]
        int n = BOX_WIDTH_PX_PER_LEVEL * k;
        int ya = p.y + pad_px - (n - 1) / 2, xa = p.x + pad_px - (n - 1) / 2;
        int yb = ya + n, xb = xa + n;
        int64_t box = sat[yb * wp1 + xb] - sat[ya * wp1 + xb] - sat[yb * wp1 + xa] + sat[ya * wp1 + xa];
        int64_t diff = box - int64_t(n * n) * qv;  // exact: n^2 (avg - in), in fixed point
        acc += wgt * (1.0LF - double(f_e) * double(1 + k)) * (double(diff) / double(n * n));
    }
    delta[i] = float(acc * SAT_STEP);
}
#endif
