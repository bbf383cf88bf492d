"""
The scanning EKF of Solanki, Al-Rubaia & Tan (IEEE/ASME T-Mech 2018), Section IV.

State (6) x = [x1, x2] = [C_p I_theta e^{-cd} / d^2, mean receiver angle of the scan],
dynamics (7)/(10) x_k = A x_{k-1} + B u_{k-1} + w_{k-1} with A = I, B = [0, 1]^T (9).
The receiver scans through Psi (Section IV, Fig. 7), and the EKF of eq. (13)-(20) uses
the last two measurements (12), y_k = [x1 g(x2_k + psi_k), x1 g(x2_{k-1} + psi_{k-1})].
The P controller (21) u_k = -G x2hat_k drives the scan mean to zero and the motor gets
u_k + psi_{k+1} - psi_k.  Observability (Section IV): det C_k != 0, which the paper
guarantees with G > 1/91 for 2 degree scan steps (eq. (24)).

Not in the paper: when measurements are missing, `ScanningEKF` predicts over the gap
with the time since its last call (mu = elapsed / dt, the time-scale graininess), adds
mu Q, and pairs the next measurement with the last one that arrived, shifted by the
control applied since (a generalisation of the second row of (17)).

Every aligner (this one and the baselines) is vectorised over independent runs: arrays
carry a leading runs axis, `step(stamp, z)` takes one measurement per run (NaN or None
when missing) and returns one motor command per run, so a node calls it with runs=1 once
per message.
"""

from dataclasses import dataclass
import math
from typing import Optional, Protocol, Sequence, Union

import numpy as np

from tskf_ros.led.intensity_model import AlignmentError, IncidenceResponse

Measurement = Union[None, float, Sequence[float], np.ndarray]

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


class ObservabilityError(AlignmentError):
    """The P gain or the scan set cannot guarantee det C_k != 0 (Section IV)."""


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


class StampClock:
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
        self.clock = StampClock(config.dt)
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

    def _g_dg(self, phi: float) -> tuple[float, float]:
        """Return g(phi) and g'(phi) of eq. (4) on plain floats (IncidenceResponse.g, .dg)."""
        a1, b1, c1, a2, b2, c2 = self.response.coefficients
        s = self.response.units_per_degree
        u = phi * s
        t1, t2 = (u - b1) / c1, (u - b2) / c2
        e1, e2 = math.exp(-(t1 * t1)), math.exp(-(t2 * t2))
        return (a1 * e1 + a2 * e2,
                s * (-2.0 * a1 * (u - b1) / (c1 * c1) * e1 - 2.0 * a2 * (u - b2) / (c2 * c2) * e2))

    def _step_one(self, stamp: float, z: Measurement) -> np.ndarray:
        """
        Make `step` for one run on plain floats: the same equations, a fifth of the time.

        (13)-(21) for a 2-state filter are a few dozen multiplications; numpy's cost per
        call on arrays of four entries is what the vectorised form spends its time on.
        The state stays in the (1, ...) arrays, read and written back once per step.
        """
        if z is None or z.__class__ is float:
            zf = math.nan if z is None else z
        else:
            zf = as_measurement(z, 1).item()
        if not math.isfinite(zf):
            zf = math.nan
        mu = self.clock.tick(stamp)
        (x1, x2), ((p00, p01), (p10, p11)) = self.x[0].tolist(), self.P[0].tolist()
        if mu is not None:
            # (13): x2^f = x2 + u_{k-1}; (14): P^f = P + mu Q
            x2 += self.u.item()
            (q00, q01), (q10, q11) = self.Q.tolist()
            p00, p01, p10, p11 = p00 + mu * q00, p01 + mu * q01, p10 + mu * q10, p11 + mu * q11
            self.u = np.zeros(1)
            self.x_prior = np.array(((x1, x2),))
            self.P_prior = np.array((((p00, p01), (p10, p11)),))
            self.x, self.P = self.x_prior.copy(), self.P_prior.copy()
        # update, eq. (15)-(20)
        z_prev, since, psi_prev = self.z_prev.item(), self.since.item(), self.psi_prev.item()
        have = zf == zf
        pair = have and z_prev == z_prev
        psi = float(self.scan[self.index])
        g1, dg1 = self._g_dg(x2 + psi)
        g2, dg2 = self._g_dg(x2 - since + psi_prev)
        # (17): C_k; (16): yhat; (12): y_k; row 2 only with a pair
        c00, c01, c10, c11 = g1, x1 * dg1, g2, x1 * dg2
        y0 = (zf - x1 * g1) if have else 0.0
        y1 = (z_prev - x1 * g2) if pair else 0.0
        if not pair:
            c10 = c11 = 0.0
        self.C = np.array((((c00, c01), (c10, c11)),))
        self.y = np.array(((y0, y1),))
        det = c00 * c11 - c01 * c10
        self.det = np.array((det if pair else math.nan,))
        tolerance = self.det_tolerance * max(abs(x1), 1e-12)
        self.singular = np.array((pair and abs(det) <= tolerance,))
        if have:
            (r00, r01), (r10, r11) = self.R.tolist()
            if not pair:
                r01 = r10 = 0.0
            # C P^f
            h00, h01 = c00 * p00 + c01 * p10, c00 * p01 + c01 * p11
            h10, h11 = c10 * p00 + c11 * p10, c10 * p01 + c11 * p11
            # S = C P^f C^T + R
            s00, s01 = h00 * c00 + h01 * c01 + r00, h00 * c10 + h01 * c11 + r01
            s10, s11 = h10 * c00 + h11 * c01 + r10, h10 * c10 + h11 * c11 + r11
            # (18): K = P^f C^T S^-1, with the 2 x 2 inverse in closed form
            ds = s00 * s11 - s01 * s10
            i00, i01, i10, i11 = s11 / ds, -s01 / ds, -s10 / ds, s00 / ds
            m00, m01 = p00 * c00 + p01 * c01, p00 * c10 + p01 * c11       # P^f C^T
            m10, m11 = p10 * c00 + p11 * c01, p10 * c10 + p11 * c11
            k00, k01 = m00 * i00 + m01 * i10, m00 * i01 + m01 * i11
            k10, k11 = m10 * i00 + m11 * i10, m10 * i01 + m11 * i11
            # (19): x = x^f + K (y_k - yhat_k)
            x1, x2 = x1 + (k00 * y0 + k01 * y1), x2 + (k10 * y0 + k11 * y1)
            # (20) in Joseph form: (I - KC) P^f (I - KC)^T + K R K^T
            a00, a01 = 1.0 - (k00 * c00 + k01 * c10), -(k00 * c01 + k01 * c11)
            a10, a11 = -(k10 * c00 + k11 * c10), 1.0 - (k10 * c01 + k11 * c11)
            t00, t01 = a00 * p00 + a01 * p10, a00 * p01 + a01 * p11
            t10, t11 = a10 * p00 + a11 * p10, a10 * p01 + a11 * p11
            v00, v01 = k00 * r00 + k01 * r10, k00 * r01 + k01 * r11
            v10, v11 = k10 * r00 + k11 * r10, k10 * r01 + k11 * r11
            p00, p01 = t00 * a00 + t01 * a01 + (v00 * k00 + v01 * k01), \
                t00 * a10 + t01 * a11 + (v00 * k10 + v01 * k11)
            p10, p11 = t10 * a00 + t11 * a01 + (v10 * k00 + v11 * k01), \
                t10 * a10 + t11 * a11 + (v10 * k10 + v11 * k11)
            self.z_prev, self.psi_prev, since = np.array((zf,)), np.array((psi,)), 0.0
        if self.config.x1_floor is not None:
            x1 = max(x1, self.config.x1_floor)
        self.updated = np.array((have,))
        # (21): u_k = -G x2hat_k
        u = -self.gain * x2
        self.x = np.array(((x1, x2),))
        self.P = np.array((((p00, p01), (p10, p11)),))
        self.u, self.since = np.array((u,)), np.array((since + u,))
        self.index = (self.index + 1) % len(self.scan)
        # motor command u_k + psi_{k+1} - psi_k
        return np.array((u + float(self.scan[self.index]) - psi,))

    def innovation_distance(self, stamp: float, z: Measurement) -> np.ndarray:
        """
        Return |z - yhat| / sqrt(S) of row 1 of (12) at the prior of `stamp`, per run.

        Not in the paper: the Mahalanobis distance of the new measurement alone against
        the prediction (13)-(14) over the time since the last call, with
        S = C_1 P^f C_1^T + R_11 and C_1 the first row of (17); nothing is changed.  For
        an innovation gate in front of `step`; NaN where z is missing.
        """
        z = as_measurement(z, self.runs)
        last = self.clock.stamp
        mu = 0.0 if last is None else max(float(stamp) - last, 0.0) / self.clock.dt
        if self.runs == 1 and type(self.response) is IncidenceResponse:
            # the same on plain floats
            (x1, x2), ((p00, p01), (p10, p11)) = self.x[0].tolist(), self.P[0].tolist()
            (q00, q01), (q10, q11) = self.Q.tolist()
            if last is not None:
                x2 += self.u.item()
            g, dg = self._g_dg(x2 + self.scan_offset)
            c1 = x1 * dg
            p00, p01, p10, p11 = p00 + mu * q00, p01 + mu * q01, p10 + mu * q10, p11 + mu * q11
            S = (g * p00 + c1 * p10) * g + (g * p01 + c1 * p11) * c1 + self.R[0, 0].item()
            d = abs(z.item() - x1 * g)
            if S > 0:
                return np.array((d / math.sqrt(S),))
            return np.array((math.inf if S == 0 and d > 0 else math.nan,))
        x2 = self.x[:, 1] + (self.u if last is not None else 0.0)
        P = self.P + mu * self.Q
        a1 = x2 + self.scan_offset
        g, dg = self.response.g(a1), self.response.dg(a1)
        C1 = np.stack([g, self.x[:, 0] * dg], axis=-1)
        S = np.einsum('ri,rij,rj->r', C1, P, C1) + self.R[0, 0]
        with np.errstate(all='ignore'):
            return np.abs(z - self.x[:, 0] * g) / np.sqrt(S)

    def correct_last_turn(self, delta: np.ndarray) -> None:
        """Account for a base that turned delta more than commanded (clamped): u_k += delta."""
        self.u = self.u + delta
        self.since = self.since + delta

    def step(self, stamp: float, z: Measurement) -> np.ndarray:
        """Run one iteration at `stamp` with z_k (NaN/None: missing); return the commands."""
        if self.runs == 1 and type(self.response) is IncidenceResponse:
            return self._step_one(stamp, z)
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
