// Colour: fovexp/colour.py (paper section 4.5; docs/METHOD.md, 5.1, 5.4). Linearise with the display's
// power law, luminance by the BT.601 weights, and the displayed frame: the grey contrast change
// and noise added to every channel of the linear foveated image, clipped, encoded.

uniform float gamma;

#ifdef ENTRY_LINEARIZE
// colour.linearize (power law): v ** gamma, every value of the image
LOCAL_2D
uniform ivec3 image_hwc;
layout(std430, binding = B_IMAGE) readonly buffer Image { float image[]; };
layout(std430, binding = B_LINEAR) writeonly buffer Linear { float linear[]; };
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= image_hwc.y || p.y >= image_hwc.x) return;
    int i = (p.y * image_hwc.y + p.x) * image_hwc.z;
    for (int ch = 0; ch < image_hwc.z; ++ch) linear[i + ch] = pow(image[i + ch], gamma);
}
#endif

#ifdef ENTRY_LUMINANCE
// colour.luminance: 0.299 R + 0.587 G + 0.114 B; grey passes through (level 0 of the pyramid)
LOCAL_2D
uniform ivec3 image_hwc;
layout(std430, binding = B_FOVEATED) readonly buffer Foveated { float foveated[]; };
layout(std430, binding = B_LUMA_PYR) writeonly buffer Luma { float luma[]; };
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= image_hwc.y || p.y >= image_hwc.x) return;
    int i = p.y * image_hwc.y + p.x, channels = image_hwc.z;
    luma[i] = channels == 3 ? dot(LUMA_BT601, vec3(foveated[3 * i], foveated[3 * i + 1], foveated[3 * i + 2]))
                            : foveated[i];
}
#endif

#ifdef ENTRY_COMPOSE
// colour.encode with the grey images added: clip(foveated + delta + noise, 0, 1) ** (1 / gamma);
// with keep_unchanged (an already-foveated frame, `foveated` its linearisation), a pixel whose
// change is exactly 0 is the frame's own (colour.encode's `unchanged`)
LOCAL_2D
uniform ivec3 image_hwc;
uniform int add_contrast;
uniform int add_noise;
uniform int keep_unchanged;
layout(std430, binding = B_IMAGE) readonly buffer Image { float image[]; };
layout(std430, binding = B_FOVEATED) readonly buffer Foveated { float foveated[]; };
layout(std430, binding = B_CONTRAST) readonly buffer Contrast { float delta[]; };
layout(std430, binding = B_NOISE) readonly buffer Noise { float noise[]; };
layout(std430, binding = B_OUTPUT) writeonly buffer Output { float outimg[]; };
void main() {
    ivec2 p = ivec2(gl_GlobalInvocationID.xy);
    if (p.x >= image_hwc.y || p.y >= image_hwc.x) return;
    int i = p.y * image_hwc.y + p.x, channels = image_hwc.z;
    float g = (add_contrast == 1 ? delta[i] : 0.0) + (add_noise == 1 ? noise[i] : 0.0);
    bool kept = keep_unchanged == 1 && g == 0.0;
    for (int ch = 0; ch < channels; ++ch)
        outimg[i * channels + ch] = kept ? image[i * channels + ch]
            : pow(clamp(foveated[i * channels + ch] + g, 0.0, 1.0), 1.0 / gamma);
}
#endif
