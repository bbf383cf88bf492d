"""
A streaming estimator session: stamped samples in, time-scale filter estimates out.

The time scale is read from the stamps (Cai et al., Section IV-C): every valid sample is a
point t_k, and its graininess is mu(t_k) = t_{k+1} - t_k (Definition 2; Bohner & Wintz
Definition 2.3).  mu(t_k) is known only when t_{k+1} arrives, so sample k+1 triggers

    step(mu(t_k), y(t_k)):  corrected estimate x(t_k | t_k)  and  predictor xhat(t_{k+1})

of the TimeScaleKalmanFilter (Bohner & Wintz Table 3, Cai Table I; see
tskf_ros.core.timescale_kalman).  Readings at or below zero are not points (Section IV-C:
an interruption, a time jump J).

Bad input never reaches the filter: non-finite values, zero stamps, stamps a ROS message
cannot hold, duplicates, stamps too old for the history, readings outside the optional
physical `measurement_range`, and readings whose innovation fails the gate are rejected
with a reason.  The gate (as robot_localization's per-sensor rejection threshold) is the
Mahalanobis distance of the innovation y - C xhat(t) - D against S = C P(t) C^T + R / period
at the predictor of the sample's own stamp.  A rejected sample is not a point, so the next
one sees the whole gap and, for a stable or integrating model, a wider gate; but for an
unstable model (Cai's A = 1 is one: the prediction's mean grows as fast as its deviation
over a gap) the gate need not widen, so after `gate_patience` consecutive gated samples
the next one that fails the gate re-initialises the filter from itself ('gate_lockout'):
a filter cannot lock itself out.  The first sample after a (re)start is not gated (there
is no prediction yet).  A late sample within the
history is inserted into the time scale, which changes mu of its left neighbour, and the
filter is re-run from there (the revised estimates are returned separately); a clock
jump forward or backward beyond a bound re-initialises the filter.  A step whose state
or covariance is non-finite or beyond `state_limit` (|x_i| or sqrt(trace P)) re-initialises
the filter from that sample ('state_health'), says so, and the next diagnostics report
is an ERROR.  Nothing non-finite is returned and P stays symmetric positive
semi-definite.  A config is validated by what it does: x0, P0 within state_limit, and a
trial step of mu = period from x0, P0 that stays finite and within state_limit.  The
module never imports rclpy.

Revisions: a sample inserted late re-runs the filter from its left neighbour, and the
revised estimates of every later point are returned again (revised=True).  A second late
sample can revise the same stamps once more; the revised outputs of one insertion come
together and in stamp order, and a later revision of a stamp supersedes an earlier one.

An input u (`add_input`) is held piecewise constant from its stamp to the next input
(zero-order hold: u(t) is in force on [t, sigma(t)) of every point t until the next
input).  An input stamp is a point of the time scale without a measurement: the filter
steps through it with y = None and the new input, so a long gap is split at the input
stamps and the input is integrated over it piece by piece (with the exact transition,
B_d = int e^{As} ds B per piece).  An input at the stamp of the newest point merges into
it (a measurement at the stamp of an input-only point likewise, also within the history
through the late-sample rewind).  Outputs at an input-only point: its predictor xhat(t)
is published on 'predicted' and its mu on the jumps, since the time scale has the point;
no 'corrected' estimate is published there (x(t|t) would just repeat the prior), so
'corrected' stays one estimate per measurement and no stamp is published twice on a topic.
An input older than the newest point is rejected ('input_late') rather than inserted: it
would change the input in force on every later interval up to the next input.  Inputs
before the first point (or after a reset) only set the input in force.  The gap and
sampling-interval statistics are over measurement points; mu over all points.

Cost: for a scalar model (n = p = 1, Cai's OWC model) an ordinary in-order sample is
taken on plain floats, through the filter's float step (`scalar_step`) and the same tests
on the same floats; anything else goes through the general path, which decides and says
why.  The two give the same outcomes bit for bit (test_session_scalar_path.py).
"""

from collections import Counter, deque
from dataclasses import dataclass, field
import math
from math import isqrt
from typing import Optional, Sequence

import numpy as np

from tskf_ros.core import irregular
from tskf_ros.core.input_rate import InputRate, report_head, worst
from tskf_ros.core.linear_models import LinearModel
from tskf_ros.core.matrices import is_psd
from tskf_ros.core.timescale_kalman import FilterError, NonRegressiveError, TRANSITIONS
from tskf_ros.core.units import MAX_STAMP_NS, NS


# reasons a sample is not used; each is a diagnostics counter
REJECT_REASONS = ('zero_stamp', 'stamp_range', 'non_finite', 'bad_size', 'bad_variance',
                  'invalid_power',
                  'out_of_range', 'gated', 'future', 'duplicate', 'too_old', 'filter_error',
                  'input_non_finite', 'input_size', 'input_late', 'input_duplicate',
                  'input_zero_stamp', 'no_input_matrix')
RESET_REASONS = ('forward_jump', 'backward_jump', 'clock_jump', 'reconfigured',
                 'state_health', 'gate_lockout', 'set_state', 'service')
# diagnostics list at most this many of the sampling intervals seen
INTERVALS_SHOWN = 20
_INF = math.inf
_empty = np.empty


class ConfigError(ValueError):
    """Estimator parameters that cannot be used; the message says why."""


def _flat(values: Sequence[float], name: str) -> np.ndarray:
    v = np.asarray(list(values), dtype=float).reshape(-1)
    if not np.all(np.isfinite(v)):
        raise ConfigError(f'{name} has non-finite entries')
    return v


def model_from_flat(*, A: Sequence[float], C: Sequence[float], Q: Sequence[float],
                    R: Sequence[float], x0: Sequence[float], P0: Sequence[float],
                    G: Sequence[float] = (), B: Sequence[float] = (),
                    D: Sequence[float] = (), name: str = 'model',
                    state_names: Sequence[str] = ()) -> LinearModel:
    """
    Build a LinearModel from row-major flat lists, inferring the shapes (ROS parameters).

    A is n x n, C is p x n, G is n x r (empty: I), Q is r x r, R is p x p, B is n x m
    (empty: none), D has p entries (empty: 0), x0 has n and P0 n x n entries.
    """
    a = _flat(A, 'A')
    n = isqrt(a.size)
    if n == 0 or n * n != a.size:
        raise ConfigError(f'A must have n^2 entries for some n >= 1, got {a.size}')
    c = _flat(C, 'C')
    if c.size == 0 or c.size % n:
        raise ConfigError(f'C must have p * {n} entries (p x n, row-major), got {c.size}')
    p = c.size // n
    g = _flat(G, 'G')
    if g.size and g.size % n:
        raise ConfigError(f'G must have {n} * r entries (n x r), got {g.size}')
    r = g.size // n if g.size else n
    arrays = {'Q': (_flat(Q, 'Q'), r * r), 'R': (_flat(R, 'R'), p * p),
              'x0': (_flat(x0, 'x0'), n), 'P0': (_flat(P0, 'P0'), n * n)}
    for key, (v, size) in arrays.items():
        if v.size != size:
            raise ConfigError(f'{key} must have {size} entries to match A and C, got {v.size}')
    b = _flat(B, 'B')
    if b.size % n:
        raise ConfigError(f'B must have {n} * m entries (n x m), got {b.size}')
    d = _flat(D, 'D')
    if d.size not in (0, p):
        raise ConfigError(f'D must have {p} entries (or none), got {d.size}')
    names = tuple(state_names) or tuple(f'x{i}' for i in range(n))
    if len(names) != n:
        raise ConfigError(f'state_names must have {n} names, got {len(names)}')
    return LinearModel(name, A=a.reshape(n, n), C=c.reshape(p, n),
                       Q=arrays['Q'][0].reshape(r, r), R=arrays['R'][0].reshape(p, p),
                       x0=arrays['x0'][0], P0=arrays['P0'][0].reshape(n, n),
                       G=g.reshape(n, r) if g.size else None,
                       B=b.reshape(n, -1) if b.size else None,
                       D=d if d.size else None, state_names=names)


@dataclass(frozen=True)
class EstimatorConfig:
    """Everything the session needs: the model, the jump form and the input bounds (s)."""

    model: LinearModel
    transition: str = 'euler'
    period: float = 1.0             # nominal sample period: classifies dense/discrete/jump
    dense_fraction: float = 0.5     # dt < dense_fraction * period: a dense stretch
    jump_factor: float = 1.5        # dt > jump_factor * period: a gap, J = dt
    max_gap: float = 5.0            # a gap longer than this raises diagnostics to WARN
    history_window: float = 10.0    # how far back a late sample may still be inserted
    history_size: int = 1000        # points kept for rewinding
    max_jump: float = 60.0          # a forward jump beyond this re-initialises
    max_backward: float = 30.0      # a backward jump beyond this re-initialises
    max_future: float = 0.0         # stamp ahead of the receiver clock by more: rejected (0 off)
    nonpositive_is_gap: bool = True  # a reading <= 0 is an interruption (a power, Cai IV-C)
    gate: float = 10.0              # Mahalanobis distance of a rejected innovation (0: off)
    gate_patience: int = 5          # consecutive gated samples before a re-initialisation
    use_message_variance: bool = False  # R_d = the sample's own variance when it is > 0
    measurement_range: tuple = ()   # (lo, hi) of a physical reading; (): any finite value
    state_limit: float = 1e9        # |x_i| or sqrt(trace P) beyond this: re-initialise
    stale_timeout: float = 10.0     # s without input: diagnostics ERROR (0: off)
    min_rate_fraction: float = 0.0  # input rate below this * 1 / period: WARN (0: off)
    rate_window: float = 10.0       # s over which the input rate is measured

    def __post_init__(self) -> None:
        """Check the bounds and that the model makes a filter; raise ConfigError if not."""
        if self.transition not in TRANSITIONS:
            raise ConfigError(f'transition must be one of {TRANSITIONS}, '
                              f'got {self.transition!r}')
        for name in ('period', 'dense_fraction', 'jump_factor', 'max_gap', 'history_window',
                     'max_jump', 'max_backward', 'max_future', 'gate', 'state_limit',
                     'stale_timeout', 'min_rate_fraction', 'rate_window'):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ConfigError(f'{name} must be finite and >= 0, got {value}')
        if not self.period > 0:
            raise ConfigError(f'period must be > 0, got {self.period}')
        if self.gate_patience < 0:
            raise ConfigError(f'gate_patience must be >= 0, got {self.gate_patience}')
        if self.history_size < 2:
            raise ConfigError(f'history_size must be >= 2, got {self.history_size}')
        if not self.max_jump > 0:
            raise ConfigError(f'max_jump must be > 0, got {self.max_jump}')
        if self.max_backward < self.history_window:
            raise ConfigError(f'max_backward ({self.max_backward} s) must be at least '
                              f'history_window ({self.history_window} s)')
        if not self.state_limit > 0:
            raise ConfigError(f'state_limit must be > 0, got {self.state_limit}')
        if self.measurement_range:
            r = tuple(self.measurement_range)
            if len(r) != 2 or not all(np.isfinite(r)) or not r[0] < r[1]:
                raise ConfigError('measurement_range must be empty or [lo, hi] with finite '
                                  f'lo < hi, got {list(r)}')
        try:
            self.model.make_filter(self.transition)
        except FilterError as exc:
            raise ConfigError(str(exc)) from None
        # a model that is not regressive at mu = period is refused step by step, not here
        self._trial(self.model.make_filter(self.transition, allow_nonregressive=True))

    def _trial(self, kf: 'object') -> None:
        """
        Refuse a model that is absurd at x0, P0 or after one nominal step from there.

        Longer jumps are not tried: an unstable model may legitimately blow up over
        max_jump (e^60 for Cai's A = 1 with the exact transition); at run time such a
        step re-initialises the filter instead ('state_health').
        """
        x0, P0 = kf.state()
        why = _unhealthy(x0, P0, self.state_limit)
        if why:
            raise ConfigError(f'the initial state is absurd: {why}')
        y = kf.C @ x0 + kf.D
        u = np.zeros(kf.B.shape[1])
        for mu in (self.period,):
            kf.set_state(x0, P0)
            try:
                with np.errstate(all='ignore'):
                    res = kf.step(mu, y, u)
            except (FilterError, ArithmeticError, np.linalg.LinAlgError) as exc:
                raise ConfigError(f'a step of mu = {mu:g} s from x0, P0 fails: {exc}') from None
            why = _unhealthy(res.x_predicted, res.P_predicted, self.state_limit)
            if why:
                raise ConfigError(f'a step of mu = period = {mu:g} s from x0, P0 gives {why}')


@dataclass(slots=True)
class Estimate:
    """One estimate: 'predicted' (xhat(t) from data before t) or 'corrected' (x(t|t))."""

    kind: str
    stamp_ns: int
    x: np.ndarray
    P: np.ndarray
    revised: bool = False


@dataclass(slots=True)
class Jump:
    """The graininess used at a point: mu(t) = sigma(t) - t."""

    stamp_ns: int
    sigma_ns: int
    revised: bool = False

    @property
    def mu(self) -> float:
        """Return mu in seconds."""
        return (self.sigma_ns - self.stamp_ns) / NS


@dataclass
class Outcome:
    """What one sample did: status, reason and message, and what to publish."""

    status: str                  # 'accepted', 'inserted', 'gap', 'rejected' or 'reset'
    reason: str = ''
    message: str = ''
    estimates: list = field(default_factory=list)
    jumps: list = field(default_factory=list)


@dataclass
class Stats:
    """Counters for diagnostics."""

    received: int = 0
    accepted: int = 0
    inserted: int = 0
    rejected: Counter = field(default_factory=Counter)
    resets: Counter = field(default_factory=Counter)
    mu_current: float = 0.0
    mu_max: float = 0.0
    gaps: dict = field(default_factory=dict)     # stamp after the gap (ns) -> J (s)
    gaps_total: int = 0
    covariance_trace: float = 0.0
    last_stamp_ns: int = 0
    # since the last diagnostics report
    gaps_over_bound: int = 0
    rejected_since: int = 0
    # sampling intervals seen, in whole nominal periods (Fang & de Callafon's kappa)
    intervals: set = field(default_factory=set)
    interval_warnings: list = field(default_factory=list)
    peak_bounds: Optional[tuple] = None
    # inputs (add_input)
    inputs_received: int = 0
    inputs_accepted: int = 0
    last_measurement_ns: int = 0


@dataclass(slots=True)
class _Point:
    stamp_ns: int
    y: object                  # ndarray (a float on the scalar path); None: input only
    x: np.ndarray              # the predictor at this point (before stepping from it)
    P: np.ndarray
    u: np.ndarray              # the input in force on [t, sigma(t))
    has_input: bool = False    # an input sample has this stamp
    variance: float = 0.0      # the sample's own variance (use_message_variance)


def _finite(*arrays: np.ndarray) -> bool:
    """Tell whether every entry is finite (plain floats for the few entries of a small state)."""
    for a in arrays:
        if a.size > 16:
            if not np.isfinite(a).all():
                return False
        elif not all(map(math.isfinite, a.ravel().tolist())):
            return False
    return True


def _health(x: np.ndarray, P: np.ndarray, limit: float) -> tuple[str, float]:
    """
    Return (why (x, P) is absurd or '', trace P) for a finite (x, P).

    Absurd: |x_i| or sqrt(trace P) beyond limit.  On plain floats: numpy's reductions
    cost more than the work on the few entries of a state.
    """
    if x.size == 1:
        big, trace = abs(x.item()), P.item()
    else:
        big = max(map(abs, x.tolist())) if x.size else 0.0
        trace = P.trace().item() if P.shape[0] > 2 else sum(P.diagonal().tolist())
    if big > limit:
        return f'|x| = {big:.3g} > state_limit = {limit:g}', math.nan
    if not trace <= limit * limit:
        return (f'sqrt(trace P) = {math.sqrt(max(trace, 0.0)):.3g} > state_limit = '
                f'{limit:g}', trace)
    return '', trace


def _unhealthy(x: np.ndarray, P: np.ndarray, limit: float) -> str:
    """Return why (x, P) is absurd (non-finite, or beyond limit), or '' if it is not."""
    if not _finite(x, P):
        return 'a non-finite state or covariance'
    return _health(x, P, limit)[0]


class EstimatorSession:
    """The filter fed from a stream of stamped samples; see the module docstring."""

    GAP_MEMORY = 1000       # gaps remembered individually for diagnostics

    def __init__(self, config: EstimatorConfig) -> None:
        self.config = config                        # derives the scalar path's bounds
        self.stats = Stats()
        self.kf = config.model.make_filter(config.transition)
        self.points: deque = deque()
        self.u = np.zeros(self.kf.B.shape[1])     # the input in force (zero-order hold)
        self.u_stamp_ns = 0                         # its stamp (0: none yet)
        self._checker: Optional[irregular.IntervalChecker] = None
        self.health_error = ''                      # why the filter re-initialised itself
        self.gated_in_a_row = 0
        self._variance = 0.0                        # of the sample being added
        self.input_rate = InputRate.for_config(config.period, config)

    @property
    def config(self) -> EstimatorConfig:
        """Return the config in use; assigning one re-derives the scalar path's bounds."""
        return self._config

    @config.setter
    def config(self, config: EstimatorConfig) -> None:
        self._config = config
        lo, hi = config.measurement_range or (-_INF, _INF)
        # the bounds add() and _append test, as the same floats: a reading is in bounds
        # exactly when low < y < inf and lo <= y <= hi
        self._bounds = (0.0 if config.nonpositive_is_gap else -_INF, lo, hi,
                        config.max_jump * NS, config.state_limit,
                        config.state_limit * config.state_limit,
                        config.gate * config.gate if config.gate > 0 else None,
                        config.model.B is not None, config.use_message_variance,
                        config.history_size, config.history_window * NS)
        self._quiet_ns = 0      # an interval between measurements known to record nothing

    # -- public API -----------------------------------------------------------------------

    def add(self, stamp_ns: int, power: float, variance: float = 0.0, *,
            now_ns: Optional[int] = None) -> Outcome:
        """Take one sample (stamp in ns, measurement, its variance); say what it did."""
        self.stats.received += 1
        if now_ns is not None:
            self.input_rate.note(now_ns)
        return self._add(stamp_ns, power, variance, now_ns)

    def _add(self, stamp_ns: int, power: float, variance: float,
             now_ns: Optional[int]) -> Outcome:
        """add() after counting: every check, then start, append, insert or restart."""
        st = self.stats
        stamp_ns = int(stamp_ns)
        cfg = self.config
        if power.__class__ is float:            # one reading: checked on plain floats
            y, values = np.array((power,)), (power,)
            lowest = power
        else:
            y = np.atleast_1d(np.asarray(power, dtype=float)).reshape(-1)
            values = y.tolist()
            lowest = min(values, default=0.0)
        if stamp_ns <= 0:
            return self._reject('zero_stamp', 'the header stamp is unset (0)')
        if stamp_ns > MAX_STAMP_NS:
            return self._reject('stamp_range', f'stamp {stamp_ns} ns is beyond what a ROS '
                                'message can hold (sec is an int32)')
        if not all(map(math.isfinite, values)):
            return self._reject('non_finite', f'measurement {y} is not finite')
        if not (math.isfinite(variance) and variance >= 0):
            return self._reject('bad_variance', f'variance {variance} is not a finite value '
                                '>= 0')
        self._variance = float(variance) if cfg.use_message_variance else 0.0
        if y.size != self.kf.p:
            return self._reject('bad_size', f'measurement has {y.size} entries, the model '
                                f'{self.kf.p}')
        if cfg.nonpositive_is_gap and lowest <= 0:
            # Cai et al. IV-C: a reading at or below zero is an interruption, not a point
            st.rejected['invalid_power'] += 1
            return Outcome('gap', 'invalid_power', f'reading {y} <= 0: an interruption')
        if cfg.measurement_range and not all(
                cfg.measurement_range[0] <= v <= cfg.measurement_range[1] for v in values):
            return self._reject('out_of_range', f'reading {y} outside measurement_range '
                                f'{list(cfg.measurement_range)}')
        if (now_ns is not None and cfg.max_future > 0
                and stamp_ns - int(now_ns) > cfg.max_future * NS):
            return self._reject('future', f'stamp {stamp_ns / NS:.9f} s is '
                                f'{(stamp_ns - now_ns) / NS:.3f} s ahead of the clock')
        if not self.points:
            return self._start(stamp_ns, y)
        last = self.points[-1].stamp_ns
        dt = stamp_ns - last
        if dt == 0 and self.points[-1].y is None:
            return self._merge_measurement(stamp_ns, y)
        if dt == 0:
            return self._reject('duplicate', f'stamp {stamp_ns / NS:.9f} s repeats the last')
        if dt > cfg.max_jump * NS:
            return self._restart('forward_jump', stamp_ns, y,
                                 f'stamp jumped {dt / NS:.3f} s forward (> max_jump)')
        if dt > 0:
            return self._append(stamp_ns, y)
        if -dt > cfg.max_backward * NS:
            return self._restart('backward_jump', stamp_ns, y,
                                 f'stamp jumped {-dt / NS:.3f} s backward (> max_backward)')
        first = self.points[0]
        if -dt > cfg.history_window * NS or stamp_ns < first.stamp_ns:
            # every point but the first is within history_window of the newest (_trim)
            if stamp_ns == first.stamp_ns and first.y is not None:
                return self._reject('duplicate', f'stamp {stamp_ns / NS:.9f} s is already a '
                                    'point')
            return self._reject('too_old', f'stamp {stamp_ns / NS:.9f} s is {-dt / NS:.3f} s '
                                'late, older than the history')
        i = self._index(stamp_ns)
        if i < len(self.points) and self.points[i].stamp_ns == stamp_ns:
            if self.points[i].y is not None:
                return self._reject('duplicate', f'stamp {stamp_ns / NS:.9f} s is already a '
                                    'point')
        return self._insert(stamp_ns, y, i)

    def add_input(self, stamp_ns: int, u: Sequence[float]) -> Outcome:
        """
        Take one input sample u (B's columns), held from its stamp to the next input.

        See the module docstring: the stamp becomes a point without a measurement (or
        merges into the newest point); a late input is rejected ('input_late').
        """
        st, cfg = self.stats, self.config
        st.inputs_received += 1
        stamp_ns = int(stamp_ns)
        u = np.asarray(u, dtype=float).reshape(-1)
        if cfg.model.B is None:
            return self._reject('no_input_matrix', 'the model has no B: input ignored')
        if stamp_ns <= 0:
            return self._reject('input_zero_stamp', 'the input header stamp is unset (0)')
        if stamp_ns > MAX_STAMP_NS:
            return self._reject('stamp_range', f'input stamp {stamp_ns} ns is beyond what a '
                                'ROS message can hold (sec is an int32)')
        if u.size != self.u.size:
            return self._reject('input_size', f'input has {u.size} entries, B has '
                                f'{self.u.size} columns')
        if not _finite(u):
            return self._reject('input_non_finite', f'input {u} is not finite')
        if not self.points:
            return self._hold(stamp_ns, u, 'accepted', 'held',
                              'input held until the first measurement')
        last = self.points[-1]
        dt = stamp_ns - last.stamp_ns
        if dt > cfg.max_jump * NS:
            self.reset('forward_jump')
            return self._hold(stamp_ns, u, 'reset', 'forward_jump',
                              f'input stamp jumped {dt / NS:.3f} s forward (> max_jump); '
                              're-initialised, input held')
        if -dt > cfg.max_backward * NS:
            self.reset('backward_jump')
            return self._hold(stamp_ns, u, 'reset', 'backward_jump',
                              f'input stamp jumped {-dt / NS:.3f} s backward (> max_backward);'
                              ' re-initialised, input held')
        if dt < 0:
            return self._reject('input_late', f'input stamp {stamp_ns / NS:.9f} s is '
                                f'{-dt / NS:.3f} s older than the newest point')
        if dt == 0:
            if last.has_input:
                return self._reject('input_duplicate', f'input stamp {stamp_ns / NS:.9f} s '
                                    'repeats the last input')
            last.u, last.has_input = u, True
            return self._hold(stamp_ns, u, 'accepted', 'merged',
                              'input merged into the newest point')
        out = self._append(stamp_ns, None, u)
        if out.status == 'accepted':
            self._hold(stamp_ns, u, 'accepted')
        return out

    def reset(self, reason: str, message: str = '') -> Outcome:
        """
        Forget the history; the next sample starts a new time scale from x0, P0.

        The input in force is kept: it is the plant's, not the filter's.
        """
        self.stats.resets[reason] += 1
        self.kf = self.config.model.make_filter(self.config.transition)
        self.points.clear()
        return Outcome('reset', reason, message or f'filter re-initialised ({reason})')

    def reconfigure(self, config: EstimatorConfig) -> Outcome:
        """Switch to a new (already validated) config, keeping the estimate if n is unchanged."""
        old_n, old_model = self.kf.n, self.config.model
        kf = config.model.make_filter(config.transition)
        self.config = config
        self._checker = None
        if kf.B.shape[1] != self.u.size:
            self.u, self.u_stamp_ns = np.zeros(kf.B.shape[1]), 0
            self.kf = kf
            return self.reset('reconfigured', f'input dimension changed -> {kf.B.shape[1]}')
        if kf.n != old_n:
            return self.reset('reconfigured', f'state dimension changed {old_n} -> {kf.n}')
        if not (np.array_equal(config.model.x0, old_model.x0)
                and np.array_equal(config.model.P0, old_model.P0)):
            self.kf = kf
            return self.reset('set_state', 'x0 / P0 changed: the estimate starts again from '
                              'them at the next sample')
        kf.set_state(self.kf.x, self.kf.P)
        self.kf = kf
        self.input_rate = InputRate.for_config(config.period, config)
        self._checker = None
        self._check_intervals()          # the same intervals may mean something else now
        return Outcome('accepted', 'reconfigured', 'new parameters in use')

    def pending(self) -> Optional[int]:
        """Stamp of the last point, whose corrected estimate waits for the next point."""
        return self.points[-1].stamp_ns if self.points else None

    def diagnostics(self, *, consume: bool = True,
                    now_ns: Optional[int] = None) -> tuple[str, str, dict]:
        """
        Return (level 'OK', 'WARN' or 'ERROR', message, values) for a diagnostics status.

        consume=True resets the since-last-report counters (gaps over the bound, rejects,
        a self re-initialisation).  With now_ns (the receiver clock) the input rate and
        staleness are judged too (InputRate).
        """
        st, cfg = self.stats, self.config
        level, msgs, values = report_head(
            self.input_rate, now_ns,
            self.health_error and f'filter re-initialised itself: {self.health_error}')
        if st.gaps_over_bound:
            level = worst(level, 'WARN')
            msgs.append(f'{st.gaps_over_bound} gap(s) longer than max_gap = {cfg.max_gap} s')
        if st.rejected_since:
            msgs.append(f'{st.rejected_since} sample(s) rejected')
        if st.interval_warnings:
            level = worst(level, 'WARN')
            msgs.append('sampling interval(s) ' + ', '.join(
                str(k) for k, _ in st.interval_warnings) + ' break observability (Fang & '
                'de Callafon Section III)')
        lengths = list(st.gaps.values())
        seen = sorted(st.intervals)
        shown = seen if len(seen) <= INTERVALS_SHOWN else (
            seen[:INTERVALS_SHOWN // 2] + ['...'] + seen[-INTERVALS_SHOWN // 2:])
        warnings = st.interval_warnings[:INTERVALS_SHOWN]
        values.update({
            'received': st.received, 'accepted': st.accepted, 'inserted_late': st.inserted,
            'inputs_received': st.inputs_received, 'inputs_accepted': st.inputs_accepted,
            'input_in_force': ' '.join(f'{v:g}' for v in self.u),
            'points_in_history': len(self.points),
            'mu_current_s': st.mu_current, 'mu_max_s': st.mu_max,
            'gaps': st.gaps_total,
            'gap_max_s': max(lengths) if lengths else 0.0,
            'gap_lengths_s': ' '.join(f'{j:g}' for j in lengths[-20:]),
            'covariance_trace': st.covariance_trace,
            'last_stamp_s': st.last_stamp_ns / NS,
            'transition': cfg.transition,
            'intervals_seen_periods': ' '.join(str(k) for k in shown),
            'intervals_seen_count': len(seen),
            'interval_warnings': ' | '.join(f'{k}: {why}' for k, why in warnings),
        })
        if st.peak_bounds is not None:
            # Theorem 2 next to the covariance the filter runs (scalar models only)
            values['theorem2_peak_bound_low'] = st.peak_bounds[0]
            values['theorem2_peak_bound_high'] = st.peak_bounds[1]
            values['covariance'] = float(self.kf.P[0, 0])
        for reason in REJECT_REASONS:
            values[f'rejected_{reason}'] = st.rejected[reason]
        for reason in RESET_REASONS:
            values[f'resets_{reason}'] = st.resets[reason]
        if consume:
            st.gaps_over_bound = 0
            st.rejected_since = 0
            self.health_error = ''
        return level, '; '.join(msgs) or 'ok', values

    # -- internals ------------------------------------------------------------------------

    def _reject(self, reason: str, message: str) -> Outcome:
        self.stats.rejected[reason] += 1
        self.stats.rejected_since += 1
        return Outcome('rejected', reason, message)

    def _start(self, stamp_ns: int, y: np.ndarray) -> Outcome:
        x, P = self.kf.state()
        self.points.append(_Point(stamp_ns, y, x, P, self.u,
                                  has_input=self.u_stamp_ns == stamp_ns,
                                  variance=self._variance))
        self.stats.last_measurement_ns = stamp_ns
        self._accepted(stamp_ns, P)
        return Outcome('accepted', estimates=[Estimate('predicted', stamp_ns, x, P)])

    def _hold(self, stamp_ns: int, u: np.ndarray, status: str, reason: str = '',
              message: str = '') -> Outcome:
        """Make u the input in force from stamp_ns on and count it."""
        self.u, self.u_stamp_ns = u, stamp_ns
        self.stats.inputs_accepted += 1
        return Outcome(status, reason, message)

    def _merge_measurement(self, stamp_ns: int, y: np.ndarray) -> Outcome:
        """Give the newest point, an input-only one, its measurement (not stepped yet)."""
        last = self.points[-1]
        last.y, last.variance = y, self._variance
        self._measured(stamp_ns)
        self._accepted(stamp_ns, last.P)
        return Outcome('accepted', 'merged', 'measurement merged into an input point')

    def _measured(self, stamp_ns: int) -> None:
        """Record the interval from the previous measurement point (gaps, kappa)."""
        st = self.stats
        if 0 < st.last_measurement_ns < stamp_ns:
            self._record_gap(st.last_measurement_ns, stamp_ns)
        st.last_measurement_ns = max(st.last_measurement_ns, stamp_ns)

    def _restart(self, reason: str, stamp_ns: int, y: np.ndarray, message: str) -> Outcome:
        self.reset(reason)
        out = self._start(stamp_ns, y)
        out.status, out.reason, out.message = 'reset', reason, message + '; re-initialised'
        return out

    def _accepted(self, stamp_ns: int, P: np.ndarray, trace: Optional[float] = None) -> None:
        st = self.stats
        st.accepted += 1
        st.last_stamp_ns = max(st.last_stamp_ns, stamp_ns)
        st.covariance_trace = float(np.trace(P)) if trace is None else trace

    def _record_gap(self, start_ns: int, end_ns: int, *, add: bool = True) -> None:
        """Keep the gap statistics: an interval longer than jump_factor * period is a jump."""
        st, cfg = self.stats, self.config
        J = (end_ns - start_ns) / NS
        if not add:
            if st.gaps.pop(end_ns, None) is not None:
                st.gaps_total -= 1
            return
        self._record_interval(J)
        if J > cfg.jump_factor * cfg.period:
            st.gaps[end_ns] = J
            st.gaps_total += 1
            if J > cfg.max_gap:
                st.gaps_over_bound += 1
            while len(st.gaps) > self.GAP_MEMORY:
                st.gaps.pop(next(iter(st.gaps)))

    def _record_interval(self, dt: float) -> None:
        """
        Keep the set of sampling intervals in nominal periods and check each new one.

        Fang & de Callafon view the stream as the discrete system of one nominal period,
        A_h = the filter's transition over `period`, measured after kappa periods.  A new
        kappa gets the Section III checks (pathological, Definition 2; degenerate,
        Definition 3) for itself only, at a cost independent of kappa
        (irregular.IntervalChecker), and for a scalar model the Theorem 2 bounds for kappa
        in [min, max] seen (closed form).  Those bounds are for Fang's filter: a
        measurement variance of R / period at every sample, where Table 3 uses R / mu.
        """
        st, cfg = self.stats, self.config
        kappa = int(round(dt / cfg.period))
        if kappa < 1 or kappa in st.intervals:
            return
        st.intervals.add(kappa)
        if len(st.intervals) == 1:          # the first: (A1) is reported with it
            self._check_intervals()
            return
        why = self._interval_checker().warning(kappa)
        if why is not None:
            st.interval_warnings = sorted(st.interval_warnings + [(kappa, why)])
        self._peak_bounds()

    def _interval_checker(self) -> irregular.IntervalChecker:
        """Return the Section III checks of this config's one-period transition (built once)."""
        if self._checker is None:
            kf = self.kf
            A_h, _, _ = kf.transition_matrices(self.config.period)
            self._checker = irregular.IntervalChecker(A_h, kf.C)
        return self._checker

    def _check_intervals(self) -> None:
        """Re-run the interval checks and the scalar bounds for all intervals seen so far."""
        st = self.stats
        st.interval_warnings, st.peak_bounds = [], None
        if not st.intervals:
            return
        check = self._interval_checker()
        st.interval_warnings = [] if check.detectable else [(1, irregular.UNDETECTABLE)]
        for k in sorted(st.intervals):
            why = check.warning(k)
            if why is not None:
                st.interval_warnings.append((k, why))
        self._peak_bounds()

    def _peak_bounds(self) -> None:
        """Theorem 2 for kappa in [min, max] seen (scalar models only)."""
        st, cfg, kf = self.stats, self.config, self.kf
        if kf.n == 1 and kf.p == 1 and st.intervals:
            A_h, Q_h, _ = kf.transition_matrices(cfg.period)
            st.peak_bounds = irregular.scalar_peak_bounds(
                float(A_h[0, 0]), float(kf.C[0, 0]), float(Q_h[0, 0]),
                float(kf.R[0, 0]) / cfg.period, min(st.intervals), max(st.intervals))

    def _append_scalar(self, stamp_ns: int, y: float, variance: float,
                       now_ns: Optional[int]) -> Optional[Outcome]:
        """
        _append of an ordinary sample to a model with n = p = 1, on plain floats.

        Ordinary: a reading and a variance that pass add()'s checks, a stamp after the
        newest point (a measurement point) by at most max_jump and not ahead of the clock,
        and a step that passes every check of _step and _append (finite, positive
        semi-definite, within state_limit, within the gate).  The filter's own float step
        is made without moving it, and the tests are those of the general path on the
        same floats, in a form that passes a subset of what it passes: anything else
        returns None having changed nothing, and add() takes the general path, which
        decides and says why.
        """
        low, lo, hi, max_jump_ns, limit, limit2, gate2, has_B, message_variance, size, \
            window_ns = self._bounds
        if not (low < y < _INF and lo <= y <= hi and 0.0 <= variance < _INF
                and stamp_ns <= MAX_STAMP_NS):
            return None
        cfg = self._config
        if (now_ns is not None and cfg.max_future > 0
                and stamp_ns - int(now_ns) > cfg.max_future * NS):
            return None
        points = self.points
        last = points[-1]
        t, y_t = last.stamp_ns, last.y
        if not 0 < stamp_ns - t <= max_jump_ns or y_t is None:
            return None
        if y_t.__class__ is not float:
            y_t = y_t.item()
        kf = self.kf
        mu = (stamp_ns - t) / NS
        if last.variance > 0:
            r = max(last.variance * mu, 1e-300)     # as _step; kf.step refuses r = inf
            if r == _INF:
                return None
        else:
            r = kf._r
        try:
            x_c, P_c, x_p, P_p, _, _ = kf.scalar_step(
                mu, kf.x.item(), kf.P.item(), y_t, last.u.tolist() if has_B else None, r)
        except FilterError:
            return None
        # finite (the step checked x_p, P_p), PSD, state_limit (_step, _health)
        if not (math.isfinite(x_c + P_c) and P_c >= 0.0 and P_p >= 0.0
                and abs(x_p) <= limit and P_p <= limit2):
            return None
        v = variance if message_variance else 0.0
        if gate2 is not None:       # _gate on the same floats
            c = kf._c[0]
            e = y - c * x_p - kf._d
            S = c * P_p * c + (v if v > 0 else kf._r / cfg.period)
            if S != 0.0 and not e * e / S <= gate2:
                return None
        # accepted: move the filter and keep the point, as _append does
        self.gated_in_a_row = 0
        self._variance = v
        xc, Pc, xp, Pp = _empty(1), _empty((1, 1)), _empty(1), _empty((1, 1))
        xc[0], Pc[0, 0], xp[0], Pp[0, 0] = x_c, P_c, x_p, P_p
        kf.x, kf.P, kf.x_corrected, kf.P_corrected = xp, Pp, xc, Pc
        points.append(_Point(stamp_ns, y, xp, Pp, self.u, False, v))
        st = self.stats
        st.mu_current = mu
        if mu > st.mu_max:
            st.mu_max = mu
        gap = stamp_ns - st.last_measurement_ns
        if gap == self._quiet_ns:
            st.last_measurement_ns = stamp_ns
        else:
            self._measured(stamp_ns)
            self._quiet_ns = gap if self._records_nothing(gap) else 0
        st.accepted += 1
        if stamp_ns > st.last_stamp_ns:
            st.last_stamp_ns = stamp_ns
        st.covariance_trace = P_p
        n = len(points)
        while n > 2 and (n > size or stamp_ns - points[1].stamp_ns > window_ns):
            points.popleft()        # _trim
            n -= 1
        return Outcome('accepted', '', '', [Estimate('corrected', t, xc, Pc, False),
                                            Estimate('predicted', stamp_ns, xp, Pp, False)],
                       [Jump(t, stamp_ns, False)])

    def _records_nothing(self, gap_ns: int) -> bool:
        """Tell whether _measured of an interval gap_ns after the last measurement is a no-op."""
        cfg = self._config
        J = gap_ns / NS
        kappa = int(round(J / cfg.period))
        return (gap_ns > 0 and kappa >= 1 and kappa in self.stats.intervals
                and not J > cfg.jump_factor * cfg.period)

    def _step(self, point: _Point, sigma_ns: int, revised: bool
              ) -> tuple[list, Jump, np.ndarray, np.ndarray]:
        """step(mu, y) from point to sigma; raises FilterError on a bad step."""
        mu = (sigma_ns - point.stamp_ns) / NS
        u = point.u if self.config.model.B is not None else None   # no B: u is 0
        if point.variance > 0 and point.y is not None:
            # the sample's own variance is its R_d = R / mu (Table 3's noise on the point);
            # a product that underflows is the smallest normal variance instead
            res = self.kf.step(mu, point.y, u, R=max(point.variance * mu, 1e-300))
        else:
            res = self.kf.step(mu, point.y, u)
        P_c, P_p = res.P_corrected, res.P_predicted
        # the filter refuses a non-finite prediction itself
        if P_c.shape[0] == 1:
            finite = math.isfinite(res.x_corrected.item() + P_c.item())
        else:
            P_c = P_c + P_c.T
            P_c *= 0.5
            finite = _finite(res.x_corrected, P_c)
        if not finite:
            raise FilterError(f'non-finite estimate at mu = {mu}')
        for name, P in (('P(t|t)', P_c), ('P(sigma(t))', P_p)):
            if not is_psd(P):
                raise FilterError(f'{name} lost positive semi-definiteness at mu = {mu}')
        est = [Estimate('predicted', sigma_ns, res.x_predicted, P_p, revised)]
        if point.y is not None:     # an input-only point has no corrected estimate
            est.insert(0, Estimate('corrected', point.stamp_ns, res.x_corrected, P_c, revised))
        return est, Jump(point.stamp_ns, sigma_ns, revised), res.x_predicted, P_p

    def _append(self, stamp_ns: int, y: Optional[np.ndarray],
                u: Optional[np.ndarray] = None) -> Outcome:
        """Step the newest point to a new one: a measurement (y) or an input (u)."""
        last = self.points[-1]
        kf = self.kf
        saved = kf.x, kf.P      # a step replaces them, never writes into them
        try:
            est, jump, x, P = self._step(last, stamp_ns, False)
        except FilterError as exc:
            kf.x, kf.P = saved              # the step may have moved it before the check
            if y is None or isinstance(exc, NonRegressiveError):
                # this mu only: the state is sound and the next sample's mu will differ
                return self._reject('filter_error', f'step refused: {exc}')
            return self._unhealthy_restart(stamp_ns, y, f'step refused: {exc}')
        why, trace = _health(x, P, self.config.state_limit)
        if why:
            kf.x, kf.P = saved
            if y is None:
                return self._reject('filter_error', f'step refused: {why}')
            return self._unhealthy_restart(stamp_ns, y, f'the step gave {why}')
        if y is not None:
            gated = self._gate(y, x, P)
            if gated:
                kf.x, kf.P = saved
                if self.gated_in_a_row >= self.config.gate_patience:
                    self.gated_in_a_row = 0
                    return self._restart('gate_lockout', stamp_ns, y, gated + (
                        f'; {self.config.gate_patience + 1} samples in a row failed the gate'))
                self.gated_in_a_row += 1
                return self._reject('gated', gated)
            self.gated_in_a_row = 0
        if u is None:
            self.points.append(_Point(stamp_ns, y, x, P, self.u, variance=self._variance))
        else:
            self.points.append(_Point(stamp_ns, None, x, P, u, has_input=True))
        self.stats.mu_current = jump.mu
        self.stats.mu_max = max(self.stats.mu_max, jump.mu)
        if y is not None:
            self._measured(stamp_ns)
            self._accepted(stamp_ns, P, trace)
        else:
            self.stats.last_stamp_ns = max(self.stats.last_stamp_ns, stamp_ns)
            self.stats.covariance_trace = trace
        self._trim()
        return Outcome('accepted', estimates=est, jumps=[jump])

    def _index(self, stamp_ns: int) -> int:
        """Return the index of the first point at or after stamp_ns, scanning from the newest."""
        i = len(self.points)
        for point in reversed(self.points):
            if point.stamp_ns < stamp_ns:
                break
            i -= 1
        return i

    def _insert(self, stamp_ns: int, y: np.ndarray, i: int) -> Outcome:
        """
        Insert a late measurement before points[i], rewind to t_j and re-run to the newest.

        j = i - 1, the left neighbour; a late measurement at the stamp of an input-only
        point merges into it (j = i).  A new point takes the input in force at t_j
        (zero-order hold).  Only the points from t_j on are taken off the history and
        re-run, so the cost grows with the lateness, not with history_size.
        """
        points = self.points
        merged = i < len(points) and points[i].stamp_ns == stamp_ns
        j = i if merged else i - 1
        tail = [points.pop() for _ in range(len(points) - j)]
        tail.reverse()                  # the old points[j:], put back if the re-run fails
        left = tail[0]
        if merged:
            rerun = [_Point(left.stamp_ns, y, left.x, left.P, left.u, left.has_input,
                            self._variance)] + tail[1:]
        else:
            rerun = [left, _Point(stamp_ns, y, np.zeros(0), np.zeros((0, 0)), left.u,
                                  variance=self._variance)] + tail[1:]
        kf = self.kf
        saved = kf.x, kf.P
        estimates, jumps = [], []
        try:
            kf.x, kf.P = left.x, left.P
            for k in range(len(rerun) - 1):
                nxt = rerun[k + 1]
                est, jump, x, P = self._step(rerun[k], nxt.stamp_ns, True)
                rerun[k + 1] = _Point(nxt.stamp_ns, nxt.y, x, P, nxt.u, nxt.has_input,
                                      nxt.variance)
                estimates += est
                jumps.append(jump)
            why = _unhealthy(kf.x, kf.P, self.config.state_limit)
            if why:
                raise FilterError(why)
        except FilterError as exc:
            points.extend(tail)
            kf.x, kf.P = saved
            return self._reject('filter_error', f're-run after a late sample refused: {exc}')
        new = 0 if merged else 1
        gated = self._gate(y, rerun[new].x, rerun[new].P) if j + new > 0 else ''
        if gated:
            points.extend(tail)
            kf.x, kf.P = saved
            return self._reject('gated', gated)
        points.extend(rerun)
        # the interval between the measurement points around it is now two intervals
        after = next((p.stamp_ns for p in rerun[new + 1:] if p.y is not None), None)
        before = next((p.stamp_ns for p in reversed(rerun[:new]) if p.y is not None), None)
        if before is None:
            head = len(points) - len(rerun)
            before = next((points[k].stamp_ns for k in range(head - 1, -1, -1)
                           if points[k].y is not None), None)
        if after is not None:
            self._record_gap(0, after, add=False)
            self._record_gap(stamp_ns, after)
        if before is not None:
            self._record_gap(before, stamp_ns)
        self.stats.last_measurement_ns = max(self.stats.last_measurement_ns, stamp_ns)
        self.stats.inserted += 1
        self.stats.mu_current = jumps[-1].mu
        self.stats.mu_max = max(self.stats.mu_max, max(jp.mu for jp in jumps))
        self._accepted(stamp_ns, kf.P)
        self._trim()
        return Outcome('inserted', 'late', f'late sample {stamp_ns / NS:.9f} s inserted; '
                       f'{len(estimates)} estimates revised', estimates, jumps)

    def _gate(self, y: np.ndarray, x: np.ndarray, P: np.ndarray) -> str:
        """Return why y fails the innovation gate at the predictor (x, P), or ''."""
        gate = self.config.gate
        if not gate > 0 or x.size == 0:
            return ''
        kf = self.kf
        if kf.p == 1:           # plain floats: e^2 / S
            C = kf.C
            Rd = self._variance if self._variance > 0 else kf.R.item() / self.config.period
            if P.shape[0] == 1:
                c = C.item()
                e = y.item() - c * x.item() - kf.D.item()
                S = c * P.item() * c + Rd
            else:
                c = C[0]
                e = y.item() - c.dot(x).item() - kf.D.item()
                S = c.dot(P).dot(c).item() + Rd
            if S == 0.0:
                return ''
            d2 = e * e / S
            if d2 <= gate * gate:
                return ''
            e = np.array((e,))
        else:
            e = y - kf.C @ x - kf.D
            Rd = (np.eye(kf.p) * self._variance if self._variance > 0
                  else kf.R / self.config.period)
            S = kf.C @ P @ kf.C.T + Rd
            with np.errstate(all='ignore'):
                try:
                    d2 = float(e @ np.linalg.solve(S, e))
                except np.linalg.LinAlgError:
                    return ''
        if d2 > gate * gate or not math.isfinite(d2):
            return (f'innovation {e} is {math.sqrt(abs(d2)):.3g} standard deviations from the '
                    f'prediction (gate {gate:g})')
        return ''

    def _unhealthy_restart(self, stamp_ns: int, y: np.ndarray, why: str) -> Outcome:
        """Re-initialise after an absurd or failed step and start again from this sample."""
        self.health_error = why
        return self._restart('state_health', stamp_ns, y, why)

    def _trim(self) -> None:
        """Keep history_size points, and the newest history_window plus the one before."""
        size, window_ns = self._bounds[-2:]
        points = self.points
        newest = points[-1].stamp_ns
        while len(points) > 2 and (
                len(points) > size or newest - points[1].stamp_ns > window_ns):
            points.popleft()
