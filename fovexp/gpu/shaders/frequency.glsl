// Frequency band and the per-impulse frequency draw: fovexp/frequency.py (paper section 4.1,
// eqs. 1-5). Band empty (no noise) where F_L >= F_H.

#include "acuity.glsl"

const float INF = uintBitsToFloat(0x7F800000u);

// frequency.blur_cutoff_cpp: 3 sigma_f = 3 / (2 pi sigma), infinite where sigma = 0 (eq. 1)
float blur_cutoff_cpp(float sigma_px) {
    return sigma_px > 0.0 ? CUTOFF_SIGMAS_F / (2.0 * PI * sigma_px) : INF;
}

// frequency.frequency_band_cpp: (F_L, F_H) in cycles/px (eqs. 1-2)
vec2 frequency_band_cpp(float ecc_deg, float ppd, float sigma_px) {
    float f_low = max(t_low_cpd(ecc_deg) / ppd, blur_cutoff_cpp(sigma_px));
    float f_high = min(t_high_cpd(ecc_deg) / ppd, NYQUIST_CPP);
    return vec2(f_low, f_high);
}

// frequency.lognormal_params: (mu_n, sigma_n) of ln f (eqs. 3-4)
vec2 lognormal_params(vec2 band_cpp, float s_f) {
    float ln_lo = log(band_cpp.x), ln_hi = log(band_cpp.y);
    float mu = 0.5 * (ln_lo + ln_hi);
    return vec2(mu, abs(0.5 * s_f * (mu - ln_lo)));
}

// erfc, fractional error below 1.2e-7 everywhere (Numerical Recipes' erfcc, Chebyshev fit)
float erfc_approx(float x) {
    float z = abs(x);
    float t = 1.0 / (1.0 + 0.5 * z);
    float r = t * exp(-z * z - 1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418
        + t * (-0.18628806 + t * (0.27886807 + t * (-1.13520398 + t * (1.48851587
        + t * (-0.82215223 + t * 0.17087277)))))))));
    return x >= 0.0 ? r : 2.0 - r;
}

float normal_cdf(float z) { return 0.5 * erfc_approx(-z * 0.70710678118654752); }
float normal_sf(float z) { return 0.5 * erfc_approx(z * 0.70710678118654752); }

// inverse normal CDF of p, given p and q = 1 - p each to full relative precision (Acklam's
// rational approximation, relative error 1.15e-9, below float precision)
float normal_ppf(float p, float q) {
    const float a1 = -3.969683028665376e+01, a2 = 2.209460984245205e+02, a3 = -2.759285104469687e+02,
                a4 = 1.383577518672690e+02, a5 = -3.066479806614716e+01, a6 = 2.506628277459239e+00;
    const float b1 = -5.447609879822406e+01, b2 = 1.615858368580409e+02, b3 = -1.556989798598866e+02,
                b4 = 6.680131188771972e+01, b5 = -1.328068155288572e+01;
    const float c1 = -7.784894002430293e-03, c2 = -3.223964580411365e-01, c3 = -2.400758277161838e+00,
                c4 = -2.549732539343734e+00, c5 = 4.374664141464968e+00, c6 = 2.938163982698783e+00;
    const float d1 = 7.784695709041462e-03, d2 = 3.224671290700398e-01, d3 = 2.445134137142996e+00,
                d4 = 3.754408661907416e+00;
    const float p_low = 0.02425;
    if (p < p_low || q < p_low) {
        float r = sqrt(-2.0 * log(min(p, q)));
        float z = (((((c1 * r + c2) * r + c3) * r + c4) * r + c5) * r + c6)
                / ((((d1 * r + d2) * r + d3) * r + d4) * r + 1.0);
        return p < q ? z : -z;
    }
    float u = p - 0.5, r = u * u;
    return (((((a1 * r + a2) * r + a3) * r + a4) * r + a5) * r + a6) * u
         / (((((b1 * r + b2) * r + b3) * r + b4) * r + b5) * r + 1.0);
}

// frequency.draw_truncated: f = exp(mu + sigma_n z), z = Phi^-1(u Phi(z_H)), the log-normal
// truncated to (0, F_H) by inversion; u and 1 - u come from the impulse (fixed per impulse)
float draw_truncated(float u, float u_complement, vec2 mu_sigma, float f_high_cpp) {
    float mu = mu_sigma.x, sigma_n = mu_sigma.y;
    if (!(sigma_n > 0.0)) return min(exp(mu), f_high_cpp);
    float z_high = (log(f_high_cpp) - mu) / sigma_n;
    float p = u * normal_cdf(z_high);
    float q = u_complement + u * normal_sf(z_high);  // 1 - p without cancellation
    return min(exp(mu + sigma_n * normal_ppf(p, q)), f_high_cpp);
}
