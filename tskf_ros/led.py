"""
LED active alignment: Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018), Sections III-V.

The light-intensity model, eq. (1)-(5):

    A = e^{-cd}                                            (1)
    E_theta(d) = I_theta e^{-cd} / d^2                     (2)
    P_in = E_theta(d) A_0 g(phi)                           (3)
    g(phi) = a1 e^{-((phi - b1)/c1)^2} + a2 e^{-((phi - b2)/c2)^2}     (4)
    V_d = C_p I_theta e^{-cd} g(phi) / d^2                 (5)

with the printed fit a1 = 0.6682, b1 = 7.752, c1 = 148.8, a2 = 0.3340, b2 = -13.57,
c2 = 325.8.  Read with phi in degrees, that g is above 98% of its peak over +-15 degrees
and still 40% of it at +-180, whereas Section V says +-15 degrees is about 20% of the
peak (the tracking zone).  So the fit's argument is phi times `units_per_degree`; the
default is the unit for which g(+-15 deg) averages 20% of the peak (17.70 units per
degree, close to a 1.8 degree stepper at 1/32 microstep, 17.78 microsteps per degree),
and `LITERAL_UNITS_PER_DEGREE` (1.0) keeps the printed reading selectable.

State (6) x = [x1, x2] = [C_p I_theta e^{-cd} / d^2, mean receiver angle of the scan],
dynamics (7)/(10) x_k = A x_{k-1} + B u_{k-1} + w_{k-1} with A = I, B = [0, 1]^T (9).
The receiver scans through Psi (Section IV, Fig. 7), and the EKF of eq. (13)-(20) uses
the last two measurements (12), y_k = [x1 g(x2_k + psi_k), x1 g(x2_{k-1} + psi_{k-1})].
The P controller (21) u_k = -G x2hat_k drives the scan mean to zero and the motor gets
u_k + psi_{k+1} - psi_k.  Observability (Section IV): det C_k != 0, which the paper
guarantees with G > 1/91 for 2 degree scan steps.

Not in the paper: when measurements are missing, `ScanningEKF` predicts over the gap
with the time since its last call (mu = elapsed / dt, the time-scale graininess), adds
mu Q, and pairs the next measurement with the last one that arrived, shifted by the
control applied since (a generalisation of the second row of (17)).

Baselines (Section V): hill-climbing with step gamma = 2 degrees, and three-point
averaging (26) gamma_p = gamma (V1 - V2) / (V1 + V2 + V3).  The simulation follows (25):
x1_k = x1_{k-1} + w1, x2_k = x2_{k-1} + beta + u_{k-1} + w2, with Table I's parameters.

All aligners are vectorised over independent runs: arrays carry a leading runs axis,
`step(stamp, z)` takes one measurement per run (NaN or None when missing) and returns
one motor command per run, so a node calls it with runs=1 once per message.
"""

from dataclasses import dataclass, field
import functools
import math
from typing import Optional, Protocol, Sequence, Union

import numpy as np
import scipy.optimize

Measurement = Union[None, float, Sequence[float], np.ndarray]

# Eq. (4), the printed Gaussian fit of the photodiode's angular response (Fig. 5).
PAPER_G_COEFFICIENTS = (0.6682, 7.752, 148.8, 0.3340, -13.57, 325.8)
LITERAL_UNITS_PER_DEGREE = 1.0
TRACKING_ANGLE = 15.0           # degrees, Section V
TRACKING_LEVEL = 0.2            # fraction of the peak intensity, Section V
MAX_INTENSITY = 3.0             # volts, Section V

# Section IV, Fig. 7: the scan set Psi (degrees), visited cyclically.
SCAN_ANGLES = (-2.0, -4.0, -6.0, -8.0, -10.0, -8.0, -6.0, -4.0, -2.0, 0.0,
               2.0, 4.0, 6.0, 8.0, 10.0, 8.0, 6.0, 4.0, 2.0, 0.0)

# Table I.
PAPER_X0 = (2.0, 0.0)
PAPER_P0 = ((100.0, 0.0), (0.0, 1000.0))
PAPER_Q_SYS = ((0.0025, 0.0), (0.0, 0.01))
PAPER_Q = ((0.25, 0.0), (0.0, 1.0))
PAPER_R_SYS = ((0.04, 0.0), (0.0, 0.04))
PAPER_R = ((1.0, 0.0), (0.0, 1.0))
PAPER_GAIN = 0.5
PAPER_DT = 0.05                 # s per iteration (Section VI: about 50 ms per EKF step)
HILL_STEP = 2.0                 # degrees, gamma of Section V


class AlignmentError(ValueError):
    """Bad configuration or bad call given to an aligner."""


class ObservabilityError(AlignmentError):
    """The P gain or the scan set cannot guarantee det C_k != 0 (Section IV)."""


def wrap_degrees(angle: np.ndarray) -> np.ndarray:
    """Wrap angles in degrees to [-180, 180)."""
    return (np.asarray(angle, dtype=float) + 180.0) % 360.0 - 180.0


def attenuation(c: float, d: float) -> float:
    """Beer's law, eq. (1): A = e^{-cd}."""
    return math.exp(-c * d)


def irradiance(intensity: float, c: float, d: float) -> float:
    """Irradiance at the receiver, eq. (2): E_theta(d) = I_theta e^{-cd} / d^2."""
    return intensity * attenuation(c, d) / d ** 2


def _fit(u: np.ndarray, coefficients: Sequence[float]) -> np.ndarray:
    """Eq. (4) in fit units: a1 e^{-((u - b1)/c1)^2} + a2 e^{-((u - b2)/c2)^2}."""
    a1, b1, c1, a2, b2, c2 = coefficients
    return a1 * np.exp(-((u - b1) / c1) ** 2) + a2 * np.exp(-((u - b2) / c2) ** 2)


def _fit_peak(coefficients: Sequence[float]) -> tuple[float, float]:
    """Return (u, g(u)) at the maximum of eq. (4), in fit units."""
    b1, b2 = coefficients[1], coefficients[4]
    lo, hi = min(b1, b2), max(b1, b2)
    res = scipy.optimize.minimize_scalar(lambda u: -float(_fit(u, coefficients)),
                                         bounds=(lo, hi), method='bounded',
                                         options={'xatol': 1e-10})
    return float(res.x), float(-res.fun)


@functools.lru_cache(maxsize=None)
def zone_units_per_degree(coefficients: tuple = PAPER_G_COEFFICIENTS, *,
                          angle: float = TRACKING_ANGLE, level: float = TRACKING_LEVEL) -> float:
    """
    Fit units per degree for which g(+-angle) averages `level` of g's peak.

    Solved with Brent's method; for the paper's fit, 15 degrees and 20% give 17.697.
    """
    _, peak = _fit_peak(coefficients)

    def excess(scale: float) -> float:
        mean = 0.5 * (_fit(angle * scale, coefficients) + _fit(-angle * scale, coefficients))
        return float(mean) / peak - level

    return float(scipy.optimize.brentq(excess, 1e-3, 1e3, xtol=1e-12))


@dataclass(frozen=True)
class IncidenceResponse:
    """
    g(phi) of eq. (4) with phi in degrees, evaluated at phi * units_per_degree.

    units_per_degree=None picks `zone_units_per_degree` (about 17.70, the default);
    pass LITERAL_UNITS_PER_DEGREE for the printed reading (phi in degrees).
    """

    coefficients: tuple = PAPER_G_COEFFICIENTS
    units_per_degree: Optional[float] = None
    peak_angle: float = field(init=False)
    peak: float = field(init=False)

    def __post_init__(self) -> None:
        if len(self.coefficients) != 6:
            raise AlignmentError('g needs six coefficients (a1, b1, c1, a2, b2, c2), '
                                 f'got {len(self.coefficients)}')
        scale = self.units_per_degree
        if scale is None:
            scale = zone_units_per_degree(tuple(self.coefficients))
        if not (math.isfinite(scale) and scale > 0.0):
            raise AlignmentError(f'units_per_degree must be positive, got {scale}')
        object.__setattr__(self, 'units_per_degree', float(scale))
        u_peak, peak = _fit_peak(self.coefficients)
        object.__setattr__(self, 'peak_angle', u_peak / scale)
        object.__setattr__(self, 'peak', peak)

    def g(self, phi: np.ndarray) -> np.ndarray:
        """Eq. (4) at phi degrees."""
        return _fit(np.asarray(phi, dtype=float) * self.units_per_degree, self.coefficients)

    def dg(self, phi: np.ndarray) -> np.ndarray:
        """g'(phi), the derivative of eq. (4) with respect to phi in degrees."""
        a1, b1, c1, a2, b2, c2 = self.coefficients
        s = self.units_per_degree
        u = np.asarray(phi, dtype=float) * s
        # d/du a e^{-((u - b)/c)^2} = -2 a (u - b) / c^2 e^{-((u - b)/c)^2}; du/dphi = s
        return s * (-2.0 * a1 * (u - b1) / c1 ** 2 * np.exp(-((u - b1) / c1) ** 2)
                    - 2.0 * a2 * (u - b2) / c2 ** 2 * np.exp(-((u - b2) / c2) ** 2))

    def voltage(self, phi: np.ndarray, *, c_p: float, intensity: float, c: float,
                d: float) -> np.ndarray:
        """Eq. (5): V_d = C_p I_theta e^{-cd} g(phi) / d^2."""
        return c_p * irradiance(intensity, c, d) * self.g(phi)


# ---------------------------------------------------------------------------------------
# Observability (Section IV)


def min_gain(scan: Sequence[float] = SCAN_ANGLES, *, max_angle: float = 180.0) -> float:
    """
    Smallest P gain with |(1 - G)/G| max|dpsi| < max_angle: 1/91 for 2 degree steps.

    Eq. (24): det C_k = 0 needs x2hat^f = (1 - G)/G (psi_k - psi_{k-1}); with
    |x2hat^f| < 180 that cannot happen when |(1 - G)/G| < 180 / max|dpsi|.
    """
    steps = np.abs(np.diff(np.r_[scan, scan[0]]))
    if np.any(steps == 0.0):
        raise ObservabilityError('consecutive scan angles must differ, or the two rows of C_k '
                                 f'coincide (det C_k = 0): scan {tuple(scan)}')
    return 1.0 / (1.0 + max_angle / float(np.max(steps)))


def check_observability(gain: float, scan: Sequence[float] = SCAN_ANGLES) -> None:
    """Raise ObservabilityError unless the gain and scan guarantee det C_k != 0 (eq. (24))."""
    if len(scan) < 2:
        raise ObservabilityError(f'the scan needs at least two angles, got {tuple(scan)}')
    g_min = min_gain(scan)
    if not (math.isfinite(gain) and gain > g_min * (1.0 + 1e-9)):
        raise ObservabilityError(
            f'P gain G = {gain:g} does not guarantee observability: need G > {g_min:.6g} '
            f'(= 1/{1.0 / g_min:g}, from |(1 - G)/G| * max|dpsi| < 180, eq. (24)); '
            'with it det C_k can vanish and the EKF loses x2')
    if gain >= 2.0:
        raise ObservabilityError(f'P gain G = {gain:g} makes x2hat <- (1 - G) x2hat diverge; '
                                 'need G < 2')


# ---------------------------------------------------------------------------------------
# Aligners


class Aligner(Protocol):
    """What the simulator (or a node) needs from an alignment algorithm."""

    runs: int

    @property
    def scan_offset(self) -> float:
        """Offset of the receiver from its mean angle at the next step (degrees)."""

    def step(self, stamp: float, z: Measurement) -> np.ndarray:
        """Take the measurement at `stamp` (NaN/None: missing); return the motor commands."""


def as_measurement(z: Measurement, runs: int) -> np.ndarray:
    """Return one float per run; None and non-finite entries become NaN (missing)."""
    if z is None:
        return np.full(runs, np.nan)
    arr = np.array(z, dtype=float).reshape(-1)
    if arr.size == 1 and runs > 1:
        arr = np.full(runs, arr[0])
    if arr.size != runs:
        raise AlignmentError(f'expected {runs} measurements, got {arr.size}')
    arr[~np.isfinite(arr)] = np.nan
    return arr


class _Clock:
    """Stamps of the calls: rejects stale ones and gives mu = elapsed / dt."""

    def __init__(self, dt: float) -> None:
        if not (math.isfinite(dt) and dt > 0.0):
            raise AlignmentError(f'dt must be positive, got {dt}')
        self.dt = float(dt)
        self.stamp: Optional[float] = None

    def tick(self, stamp: float) -> Optional[float]:
        """Advance to stamp; return mu (None at the first call)."""
        stamp = float(stamp)
        if not math.isfinite(stamp):
            raise AlignmentError(f'stamp must be finite, got {stamp}')
        if self.stamp is None:
            self.stamp = stamp
            return None
        if stamp <= self.stamp:
            raise AlignmentError(f'stale stamp {stamp!r}: not after the previous one '
                                 f'{self.stamp!r}')
        mu = (stamp - self.stamp) / self.dt
        self.stamp = stamp
        return mu


@dataclass(frozen=True)
class EKFConfig:
    """The scanning EKF's parameters (Table I defaults)."""

    x0: tuple = PAPER_X0
    P0: tuple = PAPER_P0
    Q: tuple = PAPER_Q
    R: tuple = PAPER_R
    gain: float = PAPER_GAIN
    scan: tuple = SCAN_ANGLES
    dt: float = PAPER_DT
    # Not in the paper: project x1hat onto [x1_floor, inf) after each update, enforcing
    # Section IV's assumption x1hat > 0 (None: the paper's unconstrained EKF).
    x1_floor: Optional[float] = None


class ScanningEKF:
    """
    The EKF-based alignment of Section IV, eq. (13)-(21), vectorised over runs.

    Each `step(stamp, z)` is one iteration k: predict (13)-(14) over the time since the
    previous call, update with the measurement pair (12) if z_k arrived, compute the
    control (21) and return the motor command u_k + psi_{k+1} - psi_k.  Posterior
    x, P and prior x_prior, P_prior have a leading runs axis.
    """

    def __init__(self, config: EKFConfig = EKFConfig(),
                 response: Optional[IncidenceResponse] = None, *, runs: int = 1) -> None:
        check_observability(config.gain, config.scan)
        self.config = config
        self.response = response if response is not None else IncidenceResponse()
        self.runs = int(runs)
        if self.runs < 1:
            raise AlignmentError(f'runs must be at least 1, got {runs}')
        self.scan = np.asarray(config.scan, dtype=float)
        self.gain = float(config.gain)
        self.Q = np.asarray(config.Q, dtype=float).reshape(2, 2)
        self.R = np.asarray(config.R, dtype=float).reshape(2, 2)
        x0 = np.asarray(config.x0, dtype=float).reshape(2)
        P0 = np.asarray(config.P0, dtype=float).reshape(2, 2)
        n = self.runs
        # Table I gives the first forecast: xhat_0 and P_0^f.
        self.x = np.tile(x0, (n, 1))
        self.P = np.tile(P0, (n, 1, 1))
        self.x_prior = self.x.copy()
        self.P_prior = self.P.copy()
        self.index = 0                           # k mod len(Psi): psi_k = scan[index]
        self.clock = _Clock(config.dt)
        self.u = np.zeros(n)                     # u_{k-1}, not yet in the prediction
        self.since = np.zeros(n)                 # sum of u applied since the last z
        self.z_prev = np.full(n, np.nan)         # last measurement that arrived
        self.psi_prev = np.zeros(n)              # the scan angle it was taken at
        self.y = np.zeros((n, 2))                # residual y_k - yhat_k
        self.C = np.zeros((n, 2, 2))             # C_k of (17)
        self.det = np.full(n, np.nan)            # |C_k|, NaN without a pair
        self.singular = np.zeros(n, dtype=bool)
        self.updated = np.zeros(n, dtype=bool)
        self.det_tolerance = 1e-9

    @property
    def scan_offset(self) -> float:
        """psi_k, the scan angle at which the next measurement is taken."""
        return float(self.scan[self.index])

    def predict(self, mu: float = 1.0) -> None:
        """Eq. (13)-(14) over mu nominal steps (mu = elapsed / dt, the graininess)."""
        # (13): x1^f = x1, x2^f = x2 + u_{k-1}
        self.x[:, 1] += self.u
        # (14): P^f = A P A^T + mu Q with A = I (Q is per nominal step, so it scales with mu)
        self.P = self.P + mu * self.Q
        self.u = np.zeros(self.runs)
        self.x_prior = self.x.copy()
        self.P_prior = self.P.copy()

    def h(self, x: np.ndarray, psi: float, shift: np.ndarray,
          psi_prev: np.ndarray) -> np.ndarray:
        """Eq. (16): [x1 g(x2 + psi_k), x1 g(x2 - shift + psi_{k-1})], shift = u since z_prev."""
        # (15) prints x1hat_{k-1}^f in row 2 but (17) differentiates it with respect to
        # x1hat_k^f; under (7) x1 has no input, so both rows use the current x1.
        g = self.response.g
        return np.stack([x[:, 0] * g(x[:, 1] + psi),
                         x[:, 0] * g(x[:, 1] - shift + psi_prev)], axis=-1)

    def jacobian(self, x: np.ndarray, psi: float, shift: np.ndarray,
                 psi_prev: np.ndarray) -> np.ndarray:
        """Eq. (17): C_k = dh/dx at x, one 2x2 matrix per run."""
        g, dg = self.response.g, self.response.dg
        a1 = x[:, 1] + psi
        a2 = x[:, 1] - shift + psi_prev
        C = np.empty((x.shape[0], 2, 2))
        C[:, 0, 0] = g(a1)                 # C_k,1,1 = g(x2^f + psi_k)
        C[:, 0, 1] = x[:, 0] * dg(a1)      # C_k,1,2 = x1^f g'(x2^f + psi_k)
        C[:, 1, 0] = g(a2)                 # C_k,2,1 = g(x2^f - u_{k-1} + psi_{k-1})
        C[:, 1, 1] = x[:, 0] * dg(a2)      # C_k,2,2 = x1^f g'(x2^f - u_{k-1} + psi_{k-1})
        return C

    def update(self, z: np.ndarray) -> None:
        """Eq. (18)-(20) for the runs whose z is finite; a run without z_prev uses row 1 only."""
        have = np.isfinite(z)
        pair = have & np.isfinite(self.z_prev)
        psi = self.scan_offset
        x, P = self.x, self.P
        C = self.jacobian(x, psi, self.since, self.psi_prev)
        # y_k = [z_k, z_prev] (12); yhat_k = h(x^f) (15)-(16)
        y = np.stack([np.where(have, z, 0.0), np.where(pair, self.z_prev, 0.0)], axis=-1)
        y = y - self.h(x, psi, self.since, self.psi_prev)
        # the first measurement has no partner: drop row 2 (zero row and residual)
        C[~pair, 1, :] = 0.0
        y[~pair, 1] = 0.0
        y[~have] = 0.0
        self.C = C
        self.y = y
        self.det = np.where(pair, np.linalg.det(C), np.nan)
        scale = np.maximum(np.abs(x[:, 0]), 1e-12)
        self.singular = pair & (np.abs(self.det) <= self.det_tolerance * scale)
        # R as in Table I; z_prev was already used at the previous update, so the v's of
        # successive pairs are correlated, which the paper (and this filter) ignores.
        R = np.broadcast_to(self.R, C.shape).copy()
        R[~pair, 0, 1] = R[~pair, 1, 0] = 0.0
        Ct = np.swapaxes(C, 1, 2)
        # S = C P^f C^T + R
        S = C @ P @ Ct + R
        # (18): K = P^f C^T S^-1
        K = P @ Ct @ np.linalg.inv(S)
        # (19): x = x^f + K (y_k - yhat_k)
        x_post = x + (K @ y[:, :, None])[:, :, 0]
        # (20) in Joseph form, P = (I - KC) P^f (I - KC)^T + K R K^T: equal to (I - KC) P^f
        # for this K, but it stays symmetric and positive semi-definite in floating point.
        I_KC = np.eye(2) - K @ C
        P_post = I_KC @ P @ np.swapaxes(I_KC, 1, 2) + K @ R @ np.swapaxes(K, 1, 2)
        self.x = np.where(have[:, None], x_post, x)
        self.P = np.where(have[:, None, None], P_post, P)
        if self.config.x1_floor is not None:
            self.x[:, 0] = np.maximum(self.x[:, 0], self.config.x1_floor)
        self.updated = have
        self.z_prev = np.where(have, z, self.z_prev)
        self.psi_prev = np.where(have, psi, self.psi_prev)
        self.since = np.where(have, 0.0, self.since)

    def step(self, stamp: float, z: Measurement) -> np.ndarray:
        """Run one iteration at `stamp` with z_k (NaN/None: missing); return the commands."""
        z = as_measurement(z, self.runs)
        mu = self.clock.tick(stamp)
        if mu is not None:
            self.predict(mu)
        self.update(z)
        # (21): u_k = -G x2hat_k
        u = -self.gain * self.x[:, 1]
        self.u = u
        self.since = self.since + u
        psi = self.scan_offset
        self.index = (self.index + 1) % len(self.scan)
        # motor command u_k + psi_{k+1} - psi_k
        return u + self.scan_offset - psi


class HillClimbing:
    """
    Hill-climbing (Section V): keep turning by gamma while the intensity rises.

    A missing measurement makes it wait one step in place (command 0) and measure again.
    """

    def __init__(self, gamma: float = HILL_STEP, *, runs: int = 1, dt: float = PAPER_DT) -> None:
        if not (math.isfinite(gamma) and gamma > 0.0):
            raise AlignmentError(f'gamma must be positive, got {gamma}')
        self.gamma = float(gamma)
        self.runs = int(runs)
        self.clock = _Clock(dt)
        self.direction = np.ones(self.runs)
        self.reference = np.full(self.runs, np.nan)

    @property
    def scan_offset(self) -> float:
        """Return 0: hill-climbing has no scan."""
        return 0.0

    def step(self, stamp: float, z: Measurement) -> np.ndarray:
        """Compare z with the last measurement, reverse if it did not rise, return the turn."""
        z = as_measurement(z, self.runs)
        self.clock.tick(stamp)
        have = np.isfinite(z)
        worse = have & np.isfinite(self.reference) & ~(z > self.reference)
        self.direction = np.where(worse, -self.direction, self.direction)
        self.reference = np.where(have, z, self.reference)
        return np.where(have, self.direction * self.gamma, 0.0)


class ThreePointAveraging:
    """
    Three-point averaging (Section V, eq. (26)), vectorised over runs.

    A cycle measures V3 at the current orientation, V1 after turning by +gamma and V2
    at -gamma, then turns to the new orientation by gamma_p = gamma (V1 - V2) /
    (V1 + V2 + V3) (26), as printed: with noise the denominator can come close to zero
    and gamma_p be huge.  clip=True (not in the paper) makes gamma_p 0 when the
    denominator is not positive and clips it to [-gamma, gamma], its noise-free range.
    A missing measurement repeats that phase of the cycle in place.
    """

    def __init__(self, gamma: float = HILL_STEP, *, runs: int = 1, dt: float = PAPER_DT,
                 clip: bool = False) -> None:
        if not (math.isfinite(gamma) and gamma > 0.0):
            raise AlignmentError(f'gamma must be positive, got {gamma}')
        self.gamma = float(gamma)
        self.clip = bool(clip)
        self.runs = int(runs)
        self.clock = _Clock(dt)
        self.phase = np.zeros(self.runs, dtype=int)   # 0: at origin, 1: at +gamma, 2: at -gamma
        self.v = np.zeros((self.runs, 3))             # V1, V2, V3 of the current cycle
        self.offset = np.zeros(self.runs)

    @property
    def scan_offset(self) -> float:
        """Return 0: the turns around the cycle's origin are not a scan."""
        return 0.0

    def step(self, stamp: float, z: Measurement) -> np.ndarray:
        """Record V for this phase, return the turn to the next phase's orientation."""
        z = as_measurement(z, self.runs)
        self.clock.tick(stamp)
        have = np.isfinite(z)
        g = self.gamma
        cmd = np.zeros(self.runs)
        at0, at1, at2 = (have & (self.phase == phase) for phase in range(3))
        self.v[at0, 2] = z[at0]
        self.v[at1, 0] = z[at1]
        self.v[at2, 1] = z[at2]
        cmd[at0] = g                     # origin -> +gamma
        cmd[at1] = -2.0 * g              # +gamma -> -gamma
        v1, v2, v3 = self.v[:, 0], self.v[:, 1], self.v[:, 2]
        total = v1 + v2 + v3
        with np.errstate(divide='ignore', invalid='ignore'):
            # (26): gamma_p = (gamma V1 - gamma V2) / (V1 + V2 + V3)
            gamma_p = g * (v1 - v2) / total
        if self.clip:
            gamma_p = np.clip(np.where(total > 0.0, gamma_p, 0.0), -g, g)
        gamma_p = np.where(np.isfinite(gamma_p), gamma_p, 0.0)   # 0/0: no turn
        cmd[at2] = g + gamma_p[at2]      # -gamma -> origin + gamma_p
        self.phase = np.where(have, (self.phase + 1) % 3, self.phase)
        return cmd


ALGORITHMS = ('ekf', 'hill_climbing', 'three_point')


def make_aligner(name: str, *, runs: int = 1, dt: float = PAPER_DT,
                 response: Optional[IncidenceResponse] = None,
                 ekf: Optional[EKFConfig] = None, gamma: float = HILL_STEP,
                 clip: bool = False) -> Aligner:
    """Build the aligner called `name` (one of ALGORITHMS); clip is for three_point."""
    if name == 'ekf':
        config = ekf if ekf is not None else EKFConfig(dt=dt)
        return ScanningEKF(config, response, runs=runs)
    if name == 'hill_climbing':
        return HillClimbing(gamma, runs=runs, dt=dt)
    if name == 'three_point':
        return ThreePointAveraging(gamma, runs=runs, dt=dt, clip=clip)
    raise AlignmentError(f'unknown algorithm {name!r}; expected one of {ALGORITHMS}')


# ---------------------------------------------------------------------------------------
# Simulation, eq. (25)


@dataclass(frozen=True)
class LinkConfig:
    """
    The simulated link of Section V: eq. (25) with Table I's system noise.

    beta is the transmitter's angular rate in degrees per second, added as beta * dt per
    step; Q_sys is per step.  noise is the standard deviation of v in volts (R_sys = 0.04
    is noise 0.2).  x1 starts where the peak intensity is `max_intensity`, and x2 (the
    scan mean, or the orientation for the baselines) at x2_0 degrees.  dropout is the
    probability that a measurement is missing (Bernoulli, independent per step and run).
    """

    beta: float = 1.2
    dt: float = PAPER_DT
    steps: int = 400
    noise: float = 0.2
    q_sys: tuple = (PAPER_Q_SYS[0][0], PAPER_Q_SYS[1][1])
    max_intensity: float = MAX_INTENSITY
    x2_0: float = 5.0
    dropout: float = 0.0


@dataclass
class Trajectory:
    """One simulation: time (steps,) and per-step, per-run arrays (steps, runs)."""

    t: np.ndarray
    phi: np.ndarray        # true angle of incidence, unwrapped (degrees)
    x2: np.ndarray         # true scan mean phi - psi_k (the baselines: phi)
    x1: np.ndarray         # true intensity factor
    clean: np.ndarray      # x1 g(phi), the clean measurement (V)
    z: np.ndarray          # the measurement given to the aligner, NaN when missing
    command: np.ndarray    # motor command returned by the aligner
    estimate: Optional[np.ndarray] = None   # (steps, runs, 2) posterior, EKF only


def simulate(aligner: Aligner, link: LinkConfig, rng: np.random.Generator,
             response: Optional[IncidenceResponse] = None) -> Trajectory:
    """
    Run the aligner in closed loop with eq. (25) for link.steps steps.

    Step k: the receiver at phi_k measures z_k = x1_k g(phi_k) + v_k (eq. (8)), the aligner
    returns the command c_k, and phi_{k+1} = phi_k + beta dt + c_k + w2, x1_{k+1} =
    |x1_k + w1| (kept positive, as Section IV assumes).  The noise is drawn up front in a
    fixed order, so aligners run with the same seed see the same w, v and dropouts.
    """
    response = response if response is not None else IncidenceResponse()
    n, steps = aligner.runs, int(link.steps)
    if steps < 1:
        raise AlignmentError(f'steps must be at least 1, got {steps}')
    if not 0.0 <= link.dropout < 1.0:
        raise AlignmentError(f'dropout must be in [0, 1), got {link.dropout}')
    w1 = rng.standard_normal((steps, n)) * math.sqrt(link.q_sys[0])
    w2 = rng.standard_normal((steps, n)) * math.sqrt(link.q_sys[1])
    v = rng.standard_normal((steps, n)) * link.noise
    missing = rng.random((steps, n)) < link.dropout
    t = np.arange(steps) * link.dt
    shape = (steps, n)
    out = Trajectory(t=t, phi=np.empty(shape), x2=np.empty(shape), x1=np.empty(shape),
                     clean=np.empty(shape), z=np.empty(shape), command=np.empty(shape))
    record_estimate = isinstance(aligner, ScanningEKF)
    if record_estimate:
        out.estimate = np.empty((steps, n, 2))
    x1 = np.full(n, link.max_intensity / response.peak)
    phi = np.full(n, link.x2_0 + aligner.scan_offset)
    drift = link.beta * link.dt
    for k in range(steps):
        clean = x1 * response.g(wrap_degrees(phi))
        # (8): V_d,k = x1 g(phi) + v_k
        z = np.where(missing[k], np.nan, clean + v[k])
        out.phi[k], out.x2[k], out.x1[k] = phi, phi - aligner.scan_offset, x1
        out.clean[k], out.z[k] = clean, z
        cmd = aligner.step(t[k], z)
        out.command[k] = cmd
        if record_estimate:
            out.estimate[k] = aligner.x
        # (25): x2_k = x2_{k-1} + beta + u_{k-1} + w2 (here on phi = x2 + psi, with the scan)
        phi = phi + drift + cmd + w2[k]
        x1 = np.abs(x1 + w1[k])
    return out


def tracking(traj: Trajectory, *, angle: float = TRACKING_ANGLE,
             threshold: float = TRACKING_LEVEL * MAX_INTENSITY) -> tuple[np.ndarray, np.ndarray]:
    """Tracking percentage per run (Section V): by angle |phi| <= 15 deg, by clean >= 0.6 V."""
    angular = 100.0 * np.mean(np.abs(wrap_degrees(traj.phi)) <= angle, axis=0)
    measure = 100.0 * np.mean(traj.clean >= threshold, axis=0)
    return angular, measure
