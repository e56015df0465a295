// Contrast enhancement: fovexp/contrast.py (Patney et al. 2016 as the release applies it,
// notes 3.3). Per integer blur level k a box mean of width box_width_px(k) (MATLAB
// anchoring) and out_k = avg_k + f_e (1 + k) (in - avg_k); each pixel interpolates between the
// two levels that bracket its sigma. Box means from a float64 summed-area table of the
// luminance padded with symmetric borders; the result kept is the change, out - in.

// contrast._symmetric: MATLAB 'symmetric' padding (-1 -> 0, n -> n - 1), repeated past the
// edges (period 2n) when the pad is wider than the image; GLSL's % is undefined for i < 0
int symmetric(int i, int n) {
    int m = 2 * n;
    i -= m * int(floor(float(i) / float(m)));
    return i >= n ? m - 1 - i : i;
}

#ifdef ENTRY_SAT_ROWS
// contrast._sat, first pass: prefix sums along each padded row (one invocation per row)
LOCAL_1D
uniform ivec2 image_hw;
uniform int pad_px;
layout(std430, binding = B_LUMA_PYR) readonly buffer Luma { float luma[]; };  // level 0 first
layout(std430, binding = B_SAT) writeonly buffer Sat { double sat[]; };
void main() {
    int y = int(gl_GlobalInvocationID.x);
    int h = image_hw.x, w = image_hw.y;
    int hp = h + 2 * pad_px, wp = w + 2 * pad_px;
    if (y >= hp) return;
    int sy = symmetric(y - pad_px, h);
    int row = (y + 1) * (wp + 1);
    double run = 0.0LF;
    sat[row] = 0.0LF;
    for (int x = 0; x < wp; ++x) {
        run += double(luma[sy * w + symmetric(x - pad_px, w)]);
        sat[row + x + 1] = run;
    }
}
#endif

#ifdef ENTRY_SAT_COLS
// contrast._sat, second pass: prefix sums down each column (one invocation per column)
LOCAL_1D
uniform ivec2 image_hw;
uniform int pad_px;
layout(std430, binding = B_SAT) buffer Sat { double sat[]; };
void main() {
    int x = int(gl_GlobalInvocationID.x) + 1;
    int hp = image_hw.x + 2 * pad_px, wp = image_hw.y + 2 * pad_px;
    if (x > wp) return;
    double run = 0.0LF;
    for (int y = 1; y <= hp; ++y) {
        run += sat[y * (wp + 1) + x];
        sat[y * (wp + 1) + x] = run;
    }
}
#endif

#ifdef ENTRY_CONTRAST_CHANGE
// contrast._enhance with minus = 1: the change of luminance the enhancement makes
LOCAL_2D
uniform ivec2 image_hw;
uniform int pad_px;
uniform float f_e;
layout(std430, binding = B_LUMA_PYR) readonly buffer Luma { float luma[]; };
layout(std430, binding = B_SIGMA) readonly buffer Sigma { float sigma[]; };
layout(std430, binding = B_SAT) readonly buffer Sat { double sat[]; };
layout(std430, binding = B_CONTRAST) writeonly buffer Contrast { float delta[]; };
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    int h = image_hw.x, w = image_hw.y;
    if (p.x >= w || p.y >= h) return;
    int i = p.y * w + p.x;
    float s = sigma[i];
    float v = luma[i];
    if (s <= 0.0) { delta[i] = 0.0; return; }
    int wp1 = w + 2 * pad_px + 1;
    int k0 = int(s);
    float t = s - float(k0);
    double acc = 0.0LF;
    for (int j = 0; j < 2; ++j) {
        int k = k0 + j;
        double wgt = double(j == 0 ? 1.0 - t : t);
        if (k == 0) { acc += wgt * double(v); continue; }  // width 0: the pixel itself
        // width n = contrast.box_width_px(k), MATLAB anchoring:
        // [x - floor((n - 1) / 2), x + ceil((n - 1) / 2)]
        int n = BOX_WIDTH_PX_PER_LEVEL * k;
        int ya = p.y + pad_px - (n - 1) / 2, xa = p.x + pad_px - (n - 1) / 2;
        int yb = ya + n, xb = xa + n;
        double box = sat[yb * wp1 + xb] - sat[ya * wp1 + xb] - sat[yb * wp1 + xa] + sat[ya * wp1 + xa];
        double avg = box / double(n * n);
        acc += wgt * (avg + double(f_e) * double(1 + k) * (double(v) - avg));
    }
    delta[i] = float(acc - double(v));
}
#endif
