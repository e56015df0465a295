// Acuity limits: fovexp/acuity.py (paper section 4.1; Thibos et al. 1996, extended as the
// release does, docs/METHOD.md, 5.6). The tables come from the Python module (header).

// numpy.interp on the Thibos table: linear, held constant past both ends
float thibos_interp(float ecc_deg, float table[THIBOS_N]) {
    if (ecc_deg <= THIBOS_ECC_DEG[0]) return table[0];
    for (int i = 1; i < THIBOS_N; ++i) {
        if (ecc_deg <= THIBOS_ECC_DEG[i]) {
            float slope = (table[i] - table[i - 1]) / (THIBOS_ECC_DEG[i] - THIBOS_ECC_DEG[i - 1]);
            return table[i - 1] + slope * (ecc_deg - THIBOS_ECC_DEG[i - 1]);
        }
    }
    return table[THIBOS_N - 1];
}

// resolution limit T_L(e), cycles/deg
float t_low_cpd(float ecc_deg) { return thibos_interp(ecc_deg, THIBOS_T_LOW_CPD); }

// detection limit T_H(e), cycles/deg
float t_high_cpd(float ecc_deg) { return thibos_interp(ecc_deg, THIBOS_T_HIGH_CPD); }
