"""Frequency band of the noise and the per-impulse frequency draw (paper section 4.1).

    F_L = max(T_L(e), 3 / (2 pi sigma))        (eq. 1; the blur's cut-off at 3 sigma_f)
    F_H = min(T_H(e), f_d),  f_d = 0.5 cycles/px (eq. 2; Nyquist)
    mu_n = (ln F_L + ln F_H) / 2               (eq. 3)
    sigma_n = s_f (mu_n - ln F_L) / 2          (eq. 4)
    f ~ exp(mu_n + sigma_n Z), truncated to (0, F_H)   (eq. 5 and the text after it)

T_L, T_H come from :mod:`fovexp.acuity` in cycles/deg and are converted with the local pixels
per degree. Where sigma = 0 the blur removes nothing and 3/(2 pi sigma) is infinite: the band
is empty and there is no noise. More generally, wherever F_L >= F_H (the fovea and its
surround at low blur) there is no noise at all; the release instead caps F_L at 0.5 and adds
Nyquist-frequency noise there, a defect this implementation does not copy.

The truncated draw is exact, by inversion of the normal CDF: ``z = Phi^-1(u Phi(z_H))`` with
``z_H = (ln F_H - mu_n) / sigma_n`` and ``u`` uniform in (0, 1); no rejection loop. The
release's draw (up to 10 normal draws, keeping the first below ln F_H, else mu_n;
docs/METHOD.md, 5.6) is available for the ``release`` preset.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [thibos] Thibos, L. N., et al. (1996), the paper's "thibos1996": the source of its appendix A
   limits (no DOI: which 1996 article it is could not be checked against the paper's bibliography)
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr, ndtri

from .acuity import t_high_cpd, t_low_cpd
from .geometry import cpd_to_cpp

#: Highest frequency a display reproduces, cycles/px (Nyquist; paper eq. 2).
NYQUIST_CPP = 0.5
#: The paper's blur cut-off: 3 sigma_f, where the Gaussian's response is about 1 % (eq. 1).
CUTOFF_SIGMAS_F = 3.0
#: Normal draws the release tries before falling back to the mean (docs/METHOD.md, 5.6).
RELEASE_REJECTION_TRIES = 10


def blur_cutoff_cpp(sigma_px: np.ndarray) -> np.ndarray:
    """``3 sigma_f = 3 / (2 pi sigma)`` cycles/px; infinite where sigma = 0 (paper eq. 1)."""
    sigma_px = np.asarray(sigma_px, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return np.where(sigma_px > 0, CUTOFF_SIGMAS_F / (2.0 * np.pi * sigma_px), np.inf)


def frequency_band_cpp(
    ecc_deg: np.ndarray, ppd: np.ndarray, sigma_px: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(F_L, F_H)`` in cycles/px (paper eqs. 1-2). The band is empty where ``F_L >= F_H``."""
    f_low = np.maximum(cpd_to_cpp(t_low_cpd(ecc_deg), ppd), blur_cutoff_cpp(sigma_px))
    f_high = np.minimum(cpd_to_cpp(t_high_cpd(ecc_deg), ppd), NYQUIST_CPP)
    return f_low, f_high


def lognormal_params(
    f_low_cpp: np.ndarray, f_high_cpp: np.ndarray, s_f: float
) -> tuple[np.ndarray, np.ndarray]:
    """``(mu_n, sigma_n)`` of ln f (paper eqs. 3-4); only meaningful where the band is open."""
    ln_lo, ln_hi = np.log(f_low_cpp), np.log(f_high_cpp)
    mu = 0.5 * (ln_lo + ln_hi)
    return mu, np.abs(0.5 * s_f * (mu - ln_lo))


def draw_truncated(
    u: np.ndarray, mu: np.ndarray, sigma_n: np.ndarray, f_high_cpp: np.ndarray
) -> np.ndarray:
    """Exact draw from the log-normal truncated to (0, F_H), by inversion (paper eq. 5 and
    section 4.1; docs/METHOD.md, 6.1).

    ``u`` are uniform variates in (0, 1), one per impulse (fixed per impulse, so a frame
    sequence keeps each impulse's quantile). Where ``sigma_n`` is 0 (an ``s_f`` at the bottom
    of its range underflows it) the distribution is the point ``exp(mu_n)``, its limit.
    """
    point = sigma_n == 0  # s_f so small that sigma_n underflows: the limit, f = exp(mu_n)
    # a denormal sigma_n overflows z_high to +-inf: ndtr gives 0 or 1 and f is exp(mu_n) to
    # rounding, the same limit (the stress suite drew s_f = 2.2e-309)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        z_high = (np.log(f_high_cpp) - mu) / sigma_n
        z = ndtri(np.clip(u * ndtr(z_high), 1e-300, 1.0))
        f = np.exp(np.where(point, mu, mu + sigma_n * z))
    return np.minimum(f, f_high_cpp)


def draw_release(
    normals: np.ndarray, mu: np.ndarray, sigma_n: np.ndarray, f_high_cpp: np.ndarray
) -> np.ndarray:
    """The release's draw: the first of ``normals[:, j]`` giving ln f below ln F_H, else mu_n.

    ``normals`` has shape (N, RELEASE_REJECTION_TRIES). Kept only for the ``release`` preset.
    """
    ln_f = mu[:, None] + sigma_n[:, None] * normals
    ok = ln_f < np.log(f_high_cpp)[:, None]
    first = np.argmax(ok, axis=1)
    chosen = ln_f[np.arange(ln_f.shape[0]), first]
    return np.exp(np.where(ok.any(axis=1), chosen, mu))
