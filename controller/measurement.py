"""The detection measurement model (paper eqs. 1-3): spherical camera noise as a Cartesian covariance.

Equation numbers count the numbered equations of the paper's source: eq. 1 `eqn:single_mav_model` (the
converted covariance), eq. 2 `eq:covmodel` (its diagonal form under the paper's assumptions), eq. 3 `tracecov`
(trace = kappa r^2).

A detection is a range r, an azimuth (bearing) a and an elevation e of the person seen from the camera, in
world-aligned spherical coordinates about the camera centre: x = r cos e cos a, y = r cos e sin a,
z = r sin e (ENU). The paper's inclination theta is the polar angle, theta = pi/2 - e, so its noise is the
elevation's noise. Noise (paper Sec. III-A): sigma_r = range_sigma_fraction * r (sigma_r^2 = C1 r^2),
sigma_a^2 = C2, sigma_e^2 = C3. As in the paper, the angle noises are taken about world-aligned axes at the
camera (the camera is yawed towards the person, so its image axes are close to them).

Conversion to Cartesian uses the unbiased converted measurements of Mo, Song, Zhou, Sun and Bar-Shalom (IEEE
TAES 34(3), 1998), the method the paper's eq. (1) cites: with lambda_a = exp(-sigma_a^2 / 2) and lambda_e =
exp(-sigma_e^2 / 2) (the means of cos of the angle noises), the point

    x_u = r_m cos e_m cos a_m / (lambda_a lambda_e),  y_u = r_m cos e_m sin a_m / (lambda_a lambda_e),
    z_u = r_m sin e_m / lambda_e

is unbiased, and its error covariance conditioned on the measurement (the "measurement-conditioned" form, the
expectation of (p - p_u)(p - p_u)^T over the true point given the measured one) is, with s = r_m^2 + sigma_r^2
and lambda'_a = lambda_a^4 = exp(-2 sigma_a^2), lambda'_e = lambda_e^4:

    R_xx = (1/(la^2 le^2) - 2) r^2 c_e^2 c_a^2 + s/4 (1 + la' cos 2a)(1 + le' cos 2e)
    R_yy = (1/(la^2 le^2) - 2) r^2 c_e^2 s_a^2 + s/4 (1 - la' cos 2a)(1 + le' cos 2e)
    R_zz = (1/le^2 - 2) r^2 s_e^2 + s/2 (1 - le' cos 2e)
    R_xy = (1/(la^2 le^2) - 2) r^2 c_e^2 c_a s_a + s/4 la' sin 2a (1 + le' cos 2e)
    R_xz = (1/(la le^2) - 1/la - la) r^2 c_a s_e c_e + s/2 la c_a le' sin 2e
    R_yz = (1/(la le^2) - 1/la - la) r^2 s_a s_e c_e + s/2 la s_a le' sin 2e

(la = lambda_a, le = lambda_e, and r, a, e the measured r_m, a_m, e_m; c_a = cos a, s_e = sin e, ...;
sigma_r is taken at r_m, the only range known). We chose this form over the linearised J diag(...) J^T
because it is the one the paper's eq. (1) uses, it stays correct for large angle noise, and it is a true
conditional second moment, hence positive semi-definite by construction; a floor of COV_FLOOR_M2 on the
diagonal makes it definite.
For a level view (e = 0) and small angle noise it is diagonal in the camera's range/cross/up axes with entries
close to (C1, C2, C3) r^2 (eq. 2), and its trace is the paper's kappa r^2 (eq. 3), kappa = C1 + C2 + C3:
exactly, the trace is (C1 + exp(C2 + C3) - 1) r^2 there.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

COV_FLOOR_M2 = 1e-9
"""Added to the diagonal of every converted covariance so it is positive definite even at zero range."""


@dataclass(frozen=True)
class NoiseParams:
    """Detection noise in spherical coordinates about the camera (docs/method.md#measurement-model).

    sigma_r^2 = (range_sigma_fraction * r)^2, i.e. C1 = range_sigma_fraction^2; bearing (azimuth) and
    inclination standard deviations are constant, in radians.
    """

    range_sigma_fraction: float = 0.10
    bearing_sigma_rad: float = float(np.deg2rad(1.0))
    inclination_sigma_rad: float = float(np.deg2rad(1.0))

    def __post_init__(self) -> None:
        for name in ("range_sigma_fraction", "bearing_sigma_rad", "inclination_sigma_rad"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value}")

    @property
    def kappa(self) -> float:
        """kappa = C1 + C2 + C3 of the paper's eq. (3), per square metre of range (dimensionless)."""
        return self.range_sigma_fraction**2 + self.bearing_sigma_rad**2 + self.inclination_sigma_rad**2


def paper_trace_m2(*, range_m: float, noise: NoiseParams) -> float:
    """Trace of a detection's covariance under the paper's assumptions (level view, small noise), eq. (3):
    kappa r^2 in m^2."""
    return noise.kappa * float(range_m) ** 2


def _converted_covariance(r: float, az: float, el: float, noise: NoiseParams) -> np.ndarray:
    """(3, 3) measurement-conditioned covariance of the unbiased converted point (Mo et al. 1998), with the
    range noise sigma_r = range_sigma_fraction * r taken at the given range."""
    sa, se = noise.bearing_sigma_rad, noise.inclination_sigma_rad
    la, le = np.exp(-0.5 * sa * sa), np.exp(-0.5 * se * se)
    la4, le4 = la**4, le**4
    s = r * r * (1.0 + noise.range_sigma_fraction**2)  # r_m^2 + sigma_r^2
    ca, sna, ce, sne = np.cos(az), np.sin(az), np.cos(el), np.sin(el)
    c2a, s2a, c2e, s2e = np.cos(2 * az), np.sin(2 * az), np.cos(2 * el), np.sin(2 * el)
    r2 = r * r
    k_h = 1.0 / (la * la * le * le) - 2.0
    k_xz = 1.0 / (la * le * le) - 1.0 / la - la
    up = 1.0 + le4 * c2e
    cov = np.empty((3, 3))
    cov[0, 0] = k_h * r2 * ce * ce * ca * ca + 0.25 * s * (1.0 + la4 * c2a) * up
    cov[1, 1] = k_h * r2 * ce * ce * sna * sna + 0.25 * s * (1.0 - la4 * c2a) * up
    cov[2, 2] = (1.0 / (le * le) - 2.0) * r2 * sne * sne + 0.5 * s * (1.0 - le4 * c2e)
    cov[0, 1] = cov[1, 0] = k_h * r2 * ce * ce * ca * sna + 0.25 * s * la4 * s2a * up
    cov[0, 2] = cov[2, 0] = k_xz * r2 * ca * sne * ce + 0.5 * s * la * ca * le4 * s2e
    cov[1, 2] = cov[2, 1] = k_xz * r2 * sna * sne * ce + 0.5 * s * la * sna * le4 * s2e
    cov[np.diag_indices(3)] += COV_FLOOR_M2
    return cov


def _spherical(offset_m: np.ndarray) -> tuple[float, float, float]:
    """(range m, azimuth rad, elevation rad) of an ENU offset (3,) from the camera."""
    x, y, z = offset_m
    horizontal = float(np.hypot(x, y))
    return float(np.hypot(horizontal, z)), float(np.arctan2(y, x)), float(np.arctan2(z, horizontal))


def _point(name: str, value) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be a finite (3,) position in metres, got {value!r}")
    return arr


def spherical_covariance(*, camera_position_m, target_position_m, noise: NoiseParams) -> np.ndarray:
    """(3, 3) Cartesian covariance (m^2) of a detection of target_position_m (3,) from camera_position_m (3,).

    Paper eq. (1): the unbiased converted-measurement covariance (module docstring) evaluated at this
    geometry. Symmetric positive definite.
    """
    offset = _point("target_position_m", target_position_m) - _point("camera_position_m", camera_position_m)
    return _converted_covariance(*_spherical(offset), noise)


def sample_detection(
    rng: np.random.Generator, *, camera_position_m, target_position_m, noise: NoiseParams
) -> tuple[np.ndarray, np.ndarray]:
    """Draw one noisy detection: (position_m (3,), cov_m2 (3, 3)).

    Range, azimuth and elevation get independent Gaussian noise (sigma_r from the true range), the measured
    point is converted with the unbiased (debiased) conversion, and the covariance is evaluated at the
    MEASURED point, as a real system that does not know the truth would.
    """
    camera = _point("camera_position_m", camera_position_m)
    r, az, el = _spherical(_point("target_position_m", target_position_m) - camera)
    n_r, n_a, n_e = rng.standard_normal(3)
    r_m = abs(r * (1.0 + noise.range_sigma_fraction * n_r))
    az_m = az + noise.bearing_sigma_rad * n_a
    el_m = el + noise.inclination_sigma_rad * n_e
    la = np.exp(-0.5 * noise.bearing_sigma_rad**2)
    le = np.exp(-0.5 * noise.inclination_sigma_rad**2)
    horizontal = r_m * np.cos(el_m) / (la * le)
    offset = np.array([horizontal * np.cos(az_m), horizontal * np.sin(az_m), r_m * np.sin(el_m) / le])
    position = camera + offset
    return position, _converted_covariance(r_m, az_m, el_m, noise)


def fuse_covariances(covs: Sequence[np.ndarray]) -> np.ndarray:
    """(3, 3) covariance of the fused estimate of independent measurements with covariances covs[i] (3, 3).

    Information form: (sum_i covs[i]^-1)^-1, what the recursive merging of Smith and Cheeseman (1986),
    C = C1 - C1 (C1 + C2)^-1 C1, gives when applied pairwise. Raises ValueError for an empty sequence or a
    matrix that is not symmetric positive definite.
    """
    if len(covs) == 0:
        raise ValueError("fuse_covariances needs at least one covariance")
    try:
        stack = np.array([np.asarray(c, dtype=float) for c in covs])
    except ValueError as exc:
        raise ValueError("every covariance must be a (3, 3) matrix") from exc
    if stack.shape[1:] != (3, 3) or not np.all(np.isfinite(stack)):
        raise ValueError("every covariance must be a finite (3, 3) matrix")
    asymmetry = np.abs(stack - stack.transpose(0, 2, 1)).max(axis=(1, 2))
    asymmetric = asymmetry > 1e-9 * np.abs(stack).max(axis=(1, 2))
    if np.any(asymmetric):
        raise ValueError(f"covariance {int(np.argmax(asymmetric))} is not symmetric")
    try:
        chol = np.linalg.cholesky(stack)
    except np.linalg.LinAlgError as exc:
        raise ValueError("a covariance is not positive definite") from exc
    inv_chol = np.linalg.inv(chol)
    information = np.einsum("kji,kjl->il", inv_chol, inv_chol)  # sum_k L_k^-T L_k^-1
    fused = np.linalg.inv(information)
    return 0.5 * (fused + fused.T)
