"""Acuity limits: detection and resolution thresholds of peripheral vision (paper section 4.1).

Thibos et al. 1996 measured, as a function of eccentricity, the resolution limit T_L (above it,
gratings are no longer resolved) and the detection limit T_H (above it, not even detected).
Between the two lies the band the method fills with noise. The paper's appendix table stops at
30 deg; a 4K 55" screen at 71.5 cm reaches about 44 deg in its corners, so the table is extended
as the authors' release does (docs/METHOD.md, 5.6). Values are linearly interpolated and held
constant past the last entry.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [thibos] Thibos, L. N., et al. (1996), the paper's "thibos1996": the source of its appendix A
   limits (no DOI: which 1996 article it is could not be checked against the paper's bibliography)
"""

from __future__ import annotations

import numpy as np

#: Eccentricities (deg) of the table: the paper's appendix (0..30) and the release's extension.
THIBOS_ECC_DEG = np.array([0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 70.0])
#: Resolution limit T_L, cycles/deg.
THIBOS_T_LOW_CPD = np.array([60.0, 27.0, 10.5, 8.0, 5.5, 4.8, 4.0, 3.0, 2.0])
#: Detection limit T_H, cycles/deg.
THIBOS_T_HIGH_CPD = np.array([60.0, 40.0, 26.0, 24.0, 23.0, 21.0, 20.5, 20.5, 20.5])


def t_low_cpd(ecc_deg: np.ndarray | float) -> np.ndarray:
    """Resolution limit T_L(e) in cycles/deg (paper section 4.1, appendix A table)."""
    return np.interp(ecc_deg, THIBOS_ECC_DEG, THIBOS_T_LOW_CPD)


def t_high_cpd(ecc_deg: np.ndarray | float) -> np.ndarray:
    """Detection limit T_H(e) in cycles/deg (paper section 4.1, appendix A table)."""
    return np.interp(ecc_deg, THIBOS_ECC_DEG, THIBOS_T_HIGH_CPD)
