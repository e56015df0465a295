// Viewing geometry: fovexp/geometry.py (ViewingGeometry; docs/METHOD.md, 4).
// Pixel centres at integer (x, y), x right, y down. The image covers the part of a
// geom_screen_px frame that starts at geom_origin_px; gaze_px is in the image's pixels.

uniform int geom_model;            // GEOM_EXACT, GEOM_LINEAR or GEOM_RELEASE
uniform vec2 geom_pitch_cm;        // size of one frame pixel on the screen
uniform float geom_distance_cm;
uniform float geom_ppd_constant;   // the linear and release models' constant px/deg
uniform vec2 geom_screen_px;
uniform vec2 geom_origin_px;
uniform vec2 gaze_px;

// ViewingGeometry._screen_cm: image pixel coordinates to cm from the screen centre
vec2 screen_cm(vec2 p_px) {
    return ((p_px + geom_origin_px + 0.5) - 0.5 * geom_screen_px) * geom_pitch_cm;
}

// ViewingGeometry.eccentricity_deg: the angle between the eye's rays to p and to the gaze
// (exact), on-screen px over a constant px/deg (linear, paper section 5.1), or atan(R / D)
// (release, docs/METHOD.md, 5)
float eccentricity_deg(vec2 p_px) {
    if (geom_model == GEOM_LINEAR) return length(p_px - gaze_px) / geom_ppd_constant;
    if (geom_model == GEOM_RELEASE)
        return degrees(atan(length((p_px - gaze_px) * geom_pitch_cm) / geom_distance_cm));
    vec3 u = vec3(screen_cm(p_px), geom_distance_cm);
    vec3 v = vec3(screen_cm(gaze_px), geom_distance_cm);
    return degrees(atan(length(cross(u, v)), dot(u, v)));
}

// ViewingGeometry.ppd: (pi / 180) L / pitch across the line of sight (exact), else the constant
float ppd(vec2 p_px) {
    if (geom_model != GEOM_EXACT) return geom_ppd_constant;
    vec2 u = screen_cm(p_px);
    float pitch_cm = sqrt(geom_pitch_cm.x * geom_pitch_cm.y);
    return radians(1.0) * sqrt(dot(u, u) + geom_distance_cm * geom_distance_cm) / pitch_cm;
}
