"""
A streaming alignment session: stamped intensity samples in, base position commands out.

Wraps one aligner of tskf_ros.led (the scanning EKF of Solanki et al. Section IV, or the
hill-climbing and three-point baselines of Section V) for a node that gets one message
per sample.  Each sample is one iteration: `ScanningEKF.step(stamp, z)` predicts over the
time since the last sample (mu = elapsed / dt, so a gap of missing samples grows P by
mu Q), updates, and returns the turn; the session adds it to the base angle and returns
the absolute position command a ros2_control position controller takes.

Bad input never reaches the aligner as a number it would misuse, and never stops it:

- a NaN or infinite intensity, and a negative one (a photodiode voltage cannot be
  negative; `negative_is_missing`), is a missing measurement at a known stamp: the EKF
  predicts over it and the loop goes on (the scan advances, a command is returned);
- a zero stamp, a stamp equal to the last (duplicate) or older than it (stale) is
  dropped: no step, no command;
- a stamp more than `max_backward` seconds older than the last (a clock reset, a looped
  bag) restarts the aligner from its initial state, as does a clock jump (`reset`);
- a step that would give a non-finite command or estimate restarts the aligner and
  returns no command;
- an intensity outside the optional physical `intensity_range`, or one whose innovation
  is more than `gate` standard deviations from the EKF's prediction (row 1 of (12)
  against the prior of its stamp; robot_localization's per-sensor rejection threshold),
  is a missing measurement too ('out_of_range', 'gated'): a rejected sample widens the
  next prior, so the aligner cannot lock itself out;
- an EKF state or covariance beyond `state_limit` (|x_i| or sqrt(trace P)) restarts the
  aligner ('state_health') and the next diagnostics report is an ERROR;
- a command is clamped to `max_step` degrees from the base and to the joint limits
  `base_limits`; the EKF is told the turn the base really made (its u_k), the baselines
  keep no angle and need not be told.

Every case is counted for diagnostics, with the input rate and staleness (InputRate)
when the receiver clock is given.  The module never imports rclpy.
"""

from collections import Counter
from dataclasses import dataclass, field, fields
import math
from typing import Optional, Sequence

import numpy as np

from tskf_ros import led
from tskf_ros.core.input_rate import InputRate, report_head, worst
from tskf_ros.core.units import MAX_STAMP_NS, NS

GAP_FACTOR = 1.5        # an interval longer than this many dt is a gap (samples missing)
MISSING_REASONS = ('non_finite', 'negative', 'out_of_range', 'gated')
REJECT_REASONS = ('zero_stamp', 'stamp_range', 'duplicate', 'stale', 'filter_error')
RESET_REASONS = ('backward_jump', 'clock_jump', 'reconfigured', 'filter_error',
                 'state_health')
# parameters that change in place; any other change restarts the aligner
TUNABLE = ('gain', 'Q', 'R', 'x1_floor', 'gamma', 'clip', 'negative_is_missing', 'max_gap',
           'max_backward', 'gate', 'intensity_range', 'state_limit', 'max_step',
           'base_limits', 'stale_timeout', 'min_rate_fraction', 'rate_window')


def _matrix(values: Sequence[float], name: str, *, definite: bool) -> np.ndarray:
    """Return a flat 4-entry list as a symmetric 2 x 2 matrix; raise AlignmentError if bad."""
    v = np.asarray(list(values), dtype=float)
    if v.size != 4:
        raise led.AlignmentError(f'{name} must have 4 entries (2 x 2 row-major), got {v.size}')
    if not np.all(np.isfinite(v)):
        raise led.AlignmentError(f'{name} has non-finite entries')
    m = v.reshape(2, 2)
    if not np.allclose(m, m.T, rtol=0, atol=1e-12 * max(1.0, float(np.max(np.abs(m))))):
        raise led.AlignmentError(f'{name} must be symmetric, got {m.tolist()}')
    eig = np.linalg.eigvalsh(m)
    if (definite and not eig[0] > 0) or eig[0] < 0:
        kind = 'positive definite' if definite else 'positive semi-definite'
        raise led.AlignmentError(f'{name} must be {kind}; eigenvalues {eig.tolist()}')
    return m


@dataclass(frozen=True)
class AlignmentConfig:
    """The session's settings (Table I defaults); angles in degrees, intensities in volts."""

    algorithm: str = 'ekf'                       # one of led.ALGORITHMS
    dt: float = led.PAPER_DT                     # s: the nominal sample period (mu = dt / dt)
    gain: float = led.PAPER_GAIN                 # G of the P controller (21)
    x0: tuple = led.PAPER_X0                     # xhat_0 = [x1 (V), x2 (deg)]
    P0: tuple = tuple(np.ravel(led.PAPER_P0))    # 2 x 2 row-major
    Q: tuple = tuple(np.ravel(led.PAPER_Q))
    R: tuple = tuple(np.ravel(led.PAPER_R))
    scan: tuple = led.SCAN_ANGLES                # Psi (deg), visited cyclically
    x1_floor: float = 0.0                        # keep x1hat >= this; 0: off (the paper)
    gamma: float = led.HILL_STEP                 # deg: step of the two baselines
    clip: bool = False                           # three-point: guard eq. (26)
    units_per_degree: float = 0.0                # fit units of g per degree; 0: zone unit
    base_initial: float = 0.0                    # deg: base angle when the session starts
    negative_is_missing: bool = True             # a negative intensity is a missing sample
    max_gap: float = 1.0                         # s: a longer gap sets diagnostics to WARN
    max_backward: float = 5.0                    # s: a stamp further back restarts
    gate: float = 10.0                           # innovation gate (std devs); 0: off
    intensity_range: tuple = ()                  # (lo, hi) V of a physical reading; (): any
    state_limit: float = 1e6                     # |x_i| or sqrt(trace P) beyond: restart
    max_step: float = 45.0                       # deg a command may turn the base; 0: any
    base_limits: tuple = (-360.0, 360.0)         # deg: the joint limits of the base
    stale_timeout: float = 5.0                   # s without input: diagnostics ERROR; 0 off
    min_rate_fraction: float = 0.5               # rate below this * 1 / dt: WARN; 0 off
    rate_window: float = 5.0                     # s over which the input rate is measured

    def __post_init__(self) -> None:
        """Check that the settings make a working aligner; raise AlignmentError if not."""
        if self.algorithm not in led.ALGORITHMS:
            raise led.AlignmentError(f'algorithm must be one of {led.ALGORITHMS}, '
                                     f'got {self.algorithm!r}')
        for name in ('dt', 'gain', 'x1_floor', 'gamma', 'units_per_degree', 'base_initial',
                     'max_gap', 'max_backward', 'gate', 'state_limit', 'max_step',
                     'stale_timeout', 'min_rate_fraction', 'rate_window'):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise led.AlignmentError(f'{name} must be finite, got {value}')
        for name in ('dt', 'gamma'):
            if not getattr(self, name) > 0:
                raise led.AlignmentError(f'{name} must be > 0, got {getattr(self, name)}')
        for name in ('x1_floor', 'units_per_degree', 'max_gap', 'max_backward', 'gate',
                     'max_step', 'stale_timeout', 'min_rate_fraction', 'rate_window'):
            if getattr(self, name) < 0:
                raise led.AlignmentError(f'{name} must be >= 0, got {getattr(self, name)}')
        if not self.state_limit > 0 or not self.rate_window > 0:
            raise led.AlignmentError('state_limit and rate_window must be > 0')
        for name in ('intensity_range', 'base_limits'):
            r = tuple(getattr(self, name))
            if r and (len(r) != 2 or not all(math.isfinite(v) for v in r) or not r[0] < r[1]):
                raise led.AlignmentError(f'{name} must be [lo, hi] with finite lo < hi'
                                         f'{" (or empty)" if name == "intensity_range" else ""}'
                                         f', got {list(r)}')
        if len(tuple(self.base_limits)) != 2:
            raise led.AlignmentError(f'base_limits must be [lo, hi], got {list(self.base_limits)}')
        lo, hi = self.base_limits
        if not lo <= self.base_initial <= hi:
            raise led.AlignmentError(f'base_initial {self.base_initial} deg is outside '
                                     f'base_limits {list(self.base_limits)}')
        x0 = np.asarray(list(self.x0), dtype=float)
        if x0.size != 2 or not np.all(np.isfinite(x0)):
            raise led.AlignmentError(f'x0 must be 2 finite numbers [x1, x2], got {list(x0)}')
        if float(np.max(np.abs(x0))) > self.state_limit:
            raise led.AlignmentError(f'x0 {list(x0)} is beyond state_limit {self.state_limit:g}')
        P0 = _matrix(self.P0, 'P0', definite=False)
        Q = _matrix(self.Q, 'Q', definite=False)
        # by what they do: one nominal step from P0 must stay within state_limit
        if not float(np.trace(P0 + Q)) <= self.state_limit ** 2:
            raise led.AlignmentError(f'P0 + Q (one step) has sqrt(trace) '
                                     f'{math.sqrt(float(np.trace(P0 + Q))):.3g} beyond '
                                     f'state_limit {self.state_limit:g}')
        _matrix(self.R, 'R', definite=True)
        scan = np.asarray(list(self.scan), dtype=float)
        if not np.all(np.isfinite(scan)):
            raise led.AlignmentError('scan has non-finite angles')
        # Section IV: det C_k != 0 needs G > 1/91 for 2 degree scan steps (eq. (24))
        led.check_observability(self.gain, tuple(scan))

    def ekf(self) -> led.EKFConfig:
        """Return the scanning EKF's configuration."""
        return led.EKFConfig(
            x0=tuple(float(v) for v in self.x0),
            P0=tuple(map(tuple, _matrix(self.P0, 'P0', definite=False))),
            Q=tuple(map(tuple, _matrix(self.Q, 'Q', definite=False))),
            R=tuple(map(tuple, _matrix(self.R, 'R', definite=True))),
            gain=float(self.gain), scan=tuple(float(v) for v in self.scan), dt=float(self.dt),
            x1_floor=float(self.x1_floor) if self.x1_floor > 0 else None)

    def response(self) -> led.IncidenceResponse:
        """Return g of eq. (4) in the configured unit (0: the tracking-zone unit)."""
        return led.IncidenceResponse(units_per_degree=self.units_per_degree or None)

    def make_aligner(self) -> led.Aligner:
        """Build the configured aligner for one run."""
        return led.make_aligner(self.algorithm, runs=1, dt=self.dt, response=self.response(),
                                ekf=self.ekf(), gamma=self.gamma, clip=self.clip)


@dataclass
class AlignOutcome:
    """What one sample did, and what to publish (angles in degrees)."""

    status: str                          # 'used', 'missing', 'rejected' or 'reset'
    reason: str = ''
    message: str = ''
    stamp_ns: int = 0
    command: Optional[float] = None      # absolute base position command (deg)
    turn: Optional[float] = None         # the aligner's motor command (deg)
    prior: Optional[tuple] = None        # EKF (x, P) before the update, x2 in deg
    posterior: Optional[tuple] = None    # EKF (x, P) after the update


@dataclass
class AlignStats:
    """Counters for diagnostics."""

    # alike in shape to the estimator session's Stats, but other counters
    received: int = 0
    used: int = 0
    commands: int = 0
    missing: Counter = field(default_factory=Counter)
    rejected: Counter = field(default_factory=Counter)
    resets: Counter = field(default_factory=Counter)
    gaps: int = 0
    gap_max: float = 0.0
    mu_current: float = 0.0
    mu_max: float = 0.0
    singular: int = 0
    clamped: int = 0
    last_stamp_ns: int = 0
    # since the last diagnostics report
    gaps_over_bound: int = 0
    bad_since: int = 0


class AlignmentSession:
    """One aligner fed from a stream of stamped intensity samples; see the module docstring."""

    def __init__(self, config: AlignmentConfig) -> None:
        self.config = config
        self.stats = AlignStats()
        self.base = float(config.base_initial)
        self.health_error = ''          # why the aligner restarted itself
        self.input_rate = InputRate.for_config(config.dt, config)
        self._restart()

    def _restart(self) -> None:
        self.aligner = self.config.make_aligner()
        self.origin_ns: Optional[int] = None
        self.last_ns: Optional[int] = None

    @property
    def is_ekf(self) -> bool:
        """Tell whether the aligner is the scanning EKF (the one with an estimate)."""
        return isinstance(self.aligner, led.ScanningEKF)

    # -- public API -----------------------------------------------------------------------

    def add(self, stamp_ns: int, z: float, *, now_ns: Optional[int] = None) -> AlignOutcome:
        """Take one sample (stamp in ns, intensity in V; receiver clock now); say what it did."""
        st, cfg = self.stats, self.config
        st.received += 1
        if now_ns is not None:
            self.input_rate.note(now_ns)
        stamp_ns = int(stamp_ns)
        if stamp_ns <= 0:
            return self._reject('zero_stamp', stamp_ns, 'the header stamp is unset (0)')
        if stamp_ns > MAX_STAMP_NS:
            return self._reject('stamp_range', stamp_ns, f'stamp {stamp_ns} ns is beyond what '
                                'a ROS message can hold (sec is an int32)')
        status, reason, message = 'used', '', ''
        last = self.last_ns
        if last is not None and stamp_ns == last:
            return self._reject('duplicate', stamp_ns,
                                f'stamp {stamp_ns / NS:.9f} s repeats the last')
        if last is not None and stamp_ns < last:
            back = (last - stamp_ns) / NS
            if back <= cfg.max_backward:
                return self._reject('stale', stamp_ns, f'stamp {stamp_ns / NS:.9f} s is '
                                    f'{back:.3f} s older than the last')
            self.reset('backward_jump')
            status, reason = 'reset', 'backward_jump'
            message = f'stamp jumped {back:.3f} s backward (> max_backward); restarted'
            last = None
        z = float(z)
        if not math.isfinite(z):
            status, reason, message = 'missing', 'non_finite', f'intensity {z} is not finite'
        elif z < 0 and cfg.negative_is_missing:
            status, reason, message = 'missing', 'negative', f'intensity {z:g} V < 0'
        elif cfg.intensity_range and not (
                cfg.intensity_range[0] <= z <= cfg.intensity_range[1]):
            status, reason = 'missing', 'out_of_range'
            message = f'intensity {z:g} V outside intensity_range {list(cfg.intensity_range)}'
        elif cfg.gate > 0 and self.is_ekf and last is not None:
            d = float(self.aligner.innovation_distance(
                (stamp_ns - self.origin_ns) / NS, z)[0])
            if not d <= cfg.gate:
                status, reason = 'missing', 'gated'
                message = (f'intensity {z:g} V is {d:.3g} standard deviations from the '
                           f'prediction (gate {cfg.gate:g})')
        if status == 'missing':
            st.missing[reason] += 1
            st.bad_since += 1
        if last is not None:
            self._record_interval((stamp_ns - last) / NS)
        if self.origin_ns is None:
            self.origin_ns = stamp_ns
        self.last_ns = stamp_ns
        st.last_stamp_ns = stamp_ns
        try:
            turn = float(self.aligner.step((stamp_ns - self.origin_ns) / NS,
                                           None if status == 'missing' else z)[0])
        except (led.AlignmentError, np.linalg.LinAlgError) as exc:
            return self._fail(stamp_ns, str(exc))
        prior = posterior = None
        if self.is_ekf:
            ekf = self.aligner
            prior = (ekf.x_prior[0].copy(), _sym(ekf.P_prior[0]))
            posterior = (ekf.x[0].copy(), _sym(ekf.P[0]))
            # on plain floats: numpy's reductions cost more than these eight entries
            if not all(math.isfinite(v) for a in (*prior, *posterior)
                       for v in a.ravel().tolist()):
                return self._fail(stamp_ns, 'the EKF estimate is not finite')
            big = max(max(map(abs, posterior[0].tolist())),
                      math.sqrt(max(posterior[1].trace().item(), 0.0)))
            if big > cfg.state_limit:
                self.health_error = (f'EKF state or covariance {big:.3g} beyond state_limit '
                                     f'{cfg.state_limit:g}')
                self.reset('state_health')
                return self._reject('filter_error', stamp_ns,
                                    f'{self.health_error}; aligner restarted')
            st.singular += int(ekf.singular[0])
        if not math.isfinite(turn) or not math.isfinite(self.base + turn):
            return self._fail(stamp_ns, f'the command {turn} is not finite')
        applied = self._clamp(turn)
        if applied != turn:
            st.clamped += 1
            self.aligner.correct_last_turn(np.array([applied - turn]))
        self.base += applied
        if status != 'missing':
            st.used += 1
        st.commands += 1
        return AlignOutcome(status, reason, message, stamp_ns, self.base, applied, prior,
                            posterior)

    def _clamp(self, turn: float) -> float:
        """Return the turn limited to max_step and to the joint limits base_limits."""
        cfg = self.config
        if cfg.max_step > 0:
            turn = min(max(turn, -cfg.max_step), cfg.max_step)
        lo, hi = cfg.base_limits
        return min(max(self.base + turn, lo), hi) - self.base

    def reset(self, reason: str) -> None:
        """Restart the aligner from its initial state; the base stays where it is."""
        self.stats.resets[reason] += 1
        self._restart()

    def reconfigure(self, config: AlignmentConfig) -> str:
        """Switch to a new (validated) config; in place if only TUNABLE fields changed."""
        old, self.config = self.config, config
        self.input_rate = InputRate.for_config(config.dt, config)
        changed = {f.name for f in fields(config)
                   if getattr(config, f.name) != getattr(old, f.name)}
        if changed - set(TUNABLE):
            self.reset('reconfigured')
            return f'aligner restarted ({", ".join(sorted(changed - set(TUNABLE)))} changed)'
        a = self.aligner
        if isinstance(a, led.ScanningEKF):
            ekf = config.ekf()
            a.config, a.gain = ekf, ekf.gain
            a.Q, a.R = np.asarray(ekf.Q, dtype=float), np.asarray(ekf.R, dtype=float)
        elif isinstance(a, (led.HillClimbing, led.ThreePointAveraging)):
            a.gamma = float(config.gamma)
            if isinstance(a, led.ThreePointAveraging):
                a.clip = bool(config.clip)
        return 'new parameters in use'

    def diagnostics(self, *, consume: bool = True,
                    now_ns: Optional[int] = None) -> tuple[str, str, dict]:
        """
        Return (level 'OK', 'WARN' or 'ERROR', message, values) for a diagnostics status.

        consume=True resets the since-last-report counters (long gaps, bad samples, a
        self restart).  With now_ns (receiver clock) the input rate and staleness count.
        """
        st, cfg = self.stats, self.config
        level, msgs, values = report_head(
            self.input_rate, now_ns,
            self.health_error and f'aligner restarted itself: {self.health_error}')
        if st.gaps_over_bound:
            level = worst(level, 'WARN')
            msgs.append(f'{st.gaps_over_bound} gap(s) longer than max_gap = {cfg.max_gap} s')
        if st.bad_since:
            msgs.append(f'{st.bad_since} sample(s) missing or rejected')
        values.update({
            'algorithm': cfg.algorithm, 'received': st.received,
            'used': st.used, 'commands': st.commands, 'commands_clamped': st.clamped,
            'base_command_deg': self.base,
            'gaps': st.gaps, 'gap_max_s': st.gap_max,
            'mu_current': st.mu_current, 'mu_max': st.mu_max,
            'last_stamp_s': st.last_stamp_ns / NS,
        })
        for reason in MISSING_REASONS:
            values[f'missing_{reason}'] = st.missing[reason]
        for reason in REJECT_REASONS:
            values[f'rejected_{reason}'] = st.rejected[reason]
        for reason in RESET_REASONS:
            values[f'resets_{reason}'] = st.resets[reason]
        if self.is_ekf:
            x, P = self.aligner.x[0], self.aligner.P[0]
            values.update({'x1_hat_V': float(x[0]), 'x2_hat_deg': float(x[1]),
                           'covariance_trace': float(np.trace(P)),
                           'singular_updates': st.singular})
            if st.used and not x[0] > 0:
                level = worst(level, 'WARN')
                msgs.append(f'x1hat = {x[0]:.3g} <= 0: the EKF has lost the transmitter')
        if consume:
            st.gaps_over_bound = 0
            st.bad_since = 0
            self.health_error = ''
        return level, '; '.join(msgs) or 'ok', values

    # -- internals ------------------------------------------------------------------------

    def _reject(self, reason: str, stamp_ns: int, message: str) -> AlignOutcome:
        self.stats.rejected[reason] += 1
        self.stats.bad_since += 1
        return AlignOutcome('rejected', reason, message, stamp_ns)

    def _fail(self, stamp_ns: int, message: str) -> AlignOutcome:
        """Restart the aligner after a failed step; nothing is published for this sample."""
        self.reset('filter_error')
        return self._reject('filter_error', stamp_ns, f'{message}; aligner restarted')

    def _record_interval(self, interval: float) -> None:
        st, cfg = self.stats, self.config
        mu = interval / cfg.dt
        st.mu_current = mu
        st.mu_max = max(st.mu_max, mu)
        if mu > GAP_FACTOR:
            st.gaps += 1
            st.gap_max = max(st.gap_max, interval)
            if interval > cfg.max_gap:
                st.gaps_over_bound += 1


def _sym(P: np.ndarray) -> np.ndarray:
    return (P + P.T) / 2
