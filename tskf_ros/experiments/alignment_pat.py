# Copyright 2026 The tskf_ros authors
# SPDX-License-Identifier: Apache-2.0
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""The supervised (acquire / track / re-acquire) algorithms of alignment_mc and their metrics."""

import dataclasses
from typing import Optional, Sequence, TYPE_CHECKING

import numpy as np

from tskf_ros import led
from tskf_ros.experiments import pointing_metrics
from tskf_ros.led.supervisor import STATES, Supervisor, SupervisorConfig, TRACKING

if TYPE_CHECKING:
    from matplotlib.figure import Figure

# name -> (tracker of led.ALGORITHMS, supervisor mode): '_pat' searches, acquires and
# re-acquires; ekf_reset only restarts the EKF from x0, P0 on a declared loss
PAT_ALGORITHMS = {'ekf_pat': 'ekf', 'hill_climbing_pat': 'hill_climbing',
                  'three_point_pat': 'three_point', 'ekf_reset': 'ekf'}
ACQUIRED_WITHIN = 10.0       # s: the cold-start goal
MIN_NOISE = 0.1              # V: the least sigma ekf_pat's R is set from (noise 0: R > 0)


class Recorded:
    """A Supervisor that keeps each step's states and declared losses for the metrics."""

    def __init__(self, supervisor: Supervisor) -> None:
        self.supervisor = supervisor
        self.runs = supervisor.runs
        self.states: list[np.ndarray] = []
        self.declared: list[np.ndarray] = []

    @property
    def scan_offset(self) -> float:
        """Return the supervisor's scan offset."""
        return self.supervisor.scan_offset

    def step(self, stamp: float, z: led.Measurement) -> np.ndarray:
        """Step the supervisor; keep its states and declared losses."""
        turn = self.supervisor.step(stamp, z)
        self.states.append(self.supervisor.state.copy())
        self.declared.append(self.supervisor.declared.copy())
        return turn

    def correct_last_turn(self, delta: np.ndarray) -> None:
        """Pass a clamped turn on to the supervisor."""
        self.supervisor.correct_last_turn(delta)


def ekf_settings(name: str, link: led.TrackingLinkConfig, ekf: led.EKFConfig) -> led.EKFConfig:
    """
    Return the EKF settings of the supervised `name` on `link`.

    ekf_pat's EKF is told the link's noise: R = sigma^2 I (Table I's R is 1 V^2 at every
    level of Fig. 10); the plain ekf and ekf_reset keep Table I.
    """
    if name == 'ekf_pat':
        r = max(link.noise, MIN_NOISE) ** 2
        return dataclasses.replace(ekf, R=((r, 0.0), (0.0, r)))
    return ekf


def build_pat(name: str, runs: int, link: led.TrackingLinkConfig,
              response: led.IncidenceResponse, ekf: led.EKFConfig, clip: bool,
              config: Optional[SupervisorConfig] = None,
              R: Optional[np.ndarray] = None) -> Recorded:
    """
    Build the supervised aligner `name` (one of PAT_ALGORITHMS) for `runs` runs.

    The EKF's settings are `ekf_settings`; R (runs, 2, 2), if given, replaces its R with
    one per run (runs of several links side by side).
    """
    ekf = ekf_settings(name, link, ekf)
    tracker = led.make_aligner(PAT_ALGORITHMS[name], runs=runs, dt=link.dt, response=response,
                               ekf=ekf, clip=clip)
    if R is not None and isinstance(tracker, led.ScanningEKF):
        tracker.R = np.asarray(R, dtype=float).reshape(runs, 2, 2)
    if config is None:
        # a known prior (the paper's x2_0) starts in tracking; a cold start searches
        config = SupervisorConfig(start='acquiring' if link.x2_0_spread > 0 else 'tracking')
    if name == 'ekf_reset':
        config = dataclasses.replace(config, reacquire=False, start='tracking',
                                     clip_prior=False)
    return Recorded(Supervisor(tracker, config, response))


def dark_steps(t: np.ndarray, blocked: Sequence[float]) -> np.ndarray:
    """Return the steps of stamps t (s) in the blocked interval [start, stop) (no light)."""
    if not blocked:
        return np.zeros(t.size, dtype=bool)
    return (blocked[0] <= t) & (t < blocked[1])


def metrics(traj: led.Trajectory, states: Optional[np.ndarray],
            declared: Optional[np.ndarray], *, angle: float = led.TRACKING_ANGLE,
            blocked: Sequence[float] = ()) -> dict:
    """
    Return the pointing metrics of one simulation; states / declared (steps, runs) or None.

    acquisition / reacquisition: pointing_metrics.Durations from the true |phi| (the
    cone `angle`, held HOLD_S; blocked: the light's [start, stop) s); latency: the
    supervisor's, from each declared loss to its next step tracking in the cone (None for
    a plain algorithm); false alarms: the declared losses of runs never out of the cone.
    """
    return angle_metrics(traj.t, led.wrap_degrees(traj.phi), states, declared, angle=angle,
                         blocked=blocked)


def angle_metrics(t: np.ndarray, phi: np.ndarray, states: Optional[np.ndarray],
                  declared: Optional[np.ndarray], *, angle: float = led.TRACKING_ANGLE,
                  blocked: Sequence[float] = ()) -> dict:
    """
    Return metrics() from the stamps t (steps,) and the pointing angles phi (steps, runs).

    phi is a wrapped angle of incidence (one axis) or an off-axis angle >= 0 (two axes).
    """
    dt = float(t[1] - t[0]) if t.size > 1 else 1.0
    steps, runs = phi.shape
    inside = np.abs(phi) <= angle
    acquisition, reacquisition = pointing_metrics.pointing_events(
        phi, dt, angle=angle, dark=dark_steps(t, blocked))
    lost = int(np.count_nonzero(~inside[-1]))
    out = {'lost_at_end': lost / runs, 'lost_runs': lost, 'acquisition': acquisition,
           'reacquisition': reacquisition, 'duration_s': steps * dt, 'runs': runs, 'dt': dt,
           'steps': steps}
    if declared is None or states is None:
        out.update({'latency': None, 'false_alarms_per_1000s': None, 'alarms': None,
                    'clean_runs': None})
        return out
    locked = inside & (states == TRACKING)
    clean = inside.all(axis=0)
    seconds = clean.sum() * steps * dt
    alarms = declared[:, clean].sum()
    out.update({'latency': pointing_metrics.step_latency(phi, dt, locked, declared,
                                                         angle=angle),
                'false_alarms_per_1000s': _per_1000s(alarms, seconds),
                'alarms': int(alarms), 'clean_runs': int(clean.sum())})
    return out


def _per_1000s(alarms: float, seconds: float) -> Optional[float]:
    return float(1000.0 * alarms / seconds) if seconds else None


def join_metrics(parts: Sequence[dict]) -> dict:
    """
    Return the metrics of the runs of several simulations together (metrics() of each).

    The events are joined, the runs lost at the end and the false alarms are counted over
    all the runs: the metrics of one simulation of all of them.
    """
    if len(parts) == 1:
        return parts[0]
    runs = sum(p['runs'] for p in parts)
    lost = sum(p['lost_runs'] for p in parts)
    out = {'lost_at_end': lost / runs, 'lost_runs': lost, 'duration_s': parts[0]['duration_s'],
           'runs': runs, 'dt': parts[0]['dt'], 'steps': parts[0]['steps']}
    for key in ('acquisition', 'reacquisition'):
        out[key] = pointing_metrics.Durations.join([p[key] for p in parts])
    if parts[0]['latency'] is None:
        out.update({'latency': None, 'false_alarms_per_1000s': None, 'alarms': None,
                    'clean_runs': None})
        return out
    alarms = sum(p['alarms'] for p in parts)
    clean = sum(p['clean_runs'] for p in parts)
    # the clean seconds as metrics() counts them: clean runs x steps x dt
    steps = parts[0]['steps']
    out.update({'latency': pointing_metrics.Durations.join([p['latency'] for p in parts]),
                'false_alarms_per_1000s': _per_1000s(alarms, clean * steps * parts[0]['dt']),
                'alarms': alarms, 'clean_runs': clean})
    return out


def _events() -> dict:
    return {key: [] for key in ('median', 'p90', 'events', 'ended', 'censored')}


def empty_record() -> dict:
    """Return the per-algorithm lists metrics() fills, one entry per noise level."""
    return {'lost_at_end': [], 'reacquisition_s': _events(), 'supervisor_latency_s': _events(),
            'false_alarms_per_1000s': [], 'acquired_within_10s': [],
            'acquisition_s': {**_events(), 'mean_ended': [], 'histogram': []}}


def _append(lists: dict, values: dict) -> None:
    for key, value in values.items():
        lists[key].append(value)


def record(entry: dict, m: dict) -> None:
    """Append one noise level's metrics to an algorithm's entry."""
    entry['lost_at_end'].append(m['lost_at_end'])
    _append(entry['reacquisition_s'], pointing_metrics.summary(m['reacquisition']))
    latency = m['latency']
    _append(entry['supervisor_latency_s'], pointing_metrics.summary(latency) if latency
            is not None else {key: None for key in entry['supervisor_latency_s']})
    entry['false_alarms_per_1000s'].append(m['false_alarms_per_1000s'])
    acq = m['acquisition']
    within = acq.observed & (acq.times <= ACQUIRED_WITHIN)
    entry['acquired_within_10s'].append(float(np.mean(within)) if acq.times.size else None)
    ended = acq.times[acq.observed]
    _append(entry['acquisition_s'], {
        **pointing_metrics.summary(acq),
        'mean_ended': float(np.mean(ended)) if ended.size else None,
        'histogram': pointing_metrics.histogram(acq, stop=m['duration_s'])})


def evaluate(name: str, runs: int, link: led.TrackingLinkConfig, rng: np.random.Generator,
             response: led.IncidenceResponse, ekf: led.EKFConfig, clip: bool,
             config: Optional[SupervisorConfig] = None
             ) -> tuple[np.ndarray, np.ndarray, dict, led.Trajectory, Optional[Recorded]]:
    """
    Run one algorithm (supervised or of led.ALGORITHMS, P controller).

    Return the tracking % per run (angular, measure), the metrics, the trajectory and the
    supervisor's record (None for a plain algorithm).
    """
    if name in PAT_ALGORITHMS:
        aligner: Optional[Recorded] = build_pat(name, runs, link, response, ekf, clip, config)
        traj = led.simulate_tracking(aligner, link, rng, response)
        m = metrics(traj, np.array(aligner.states), np.array(aligner.declared),
                    blocked=link.blocked)
    else:
        aligner = None
        traj = led.simulate_tracking(led.make_aligner(name, runs=runs, dt=link.dt,
                                                      response=response, ekf=ekf, clip=clip),
                                     link, rng, response)
        m = metrics(traj, None, None, blocked=link.blocked)
    angular, measure = led.tracking(traj, threshold=led.TRACKING_LEVEL * link.max_intensity)
    return angular, measure, m, traj, aligner


def plot_pat_run(traj: led.Trajectory, record: Recorded, *, run: int = 0,
                 title: str) -> 'Figure':
    """One supervised run in time: angle of incidence and base, the state, the intensity."""
    from matplotlib.figure import Figure  # here: 0.7 s to import
    fig = Figure(figsize=(7.5, 6.5))
    axes = fig.subplots(3, 1, sharex=True, gridspec_kw={'height_ratios': [3, 1, 2]})
    t = traj.t
    base = np.cumsum(np.r_[0.0, traj.command[:-1, run]])
    states = np.array(record.states)[:, run]
    declared = np.nonzero(np.array(record.declared)[:, run])[0]
    axes[0].plot(t, traj.phi[:, run], 'k', lw=1.0, label=r'angle of incidence $\phi$')
    axes[0].plot(t, base, color='tab:blue', lw=0.9, label='base angle (from its start)')
    for s in (-led.TRACKING_ANGLE, led.TRACKING_ANGLE):
        axes[0].axhline(s, color='tab:red', ls=':', lw=0.8)
    for i, k in enumerate(declared):
        axes[0].axvline(t[k], color='tab:red', lw=0.8, alpha=0.6,
                        label='declared loss' if i == 0 else None)
    axes[0].set_ylabel('angle (deg)')
    axes[1].step(t, states, where='post', color='tab:purple', lw=1.2)
    axes[1].set_yticks(range(len(STATES)), STATES)
    axes[1].set_ylabel('state')
    axes[2].plot(t, traj.z[:, run], color='0.6', lw=0.7, label='measured')
    axes[2].plot(t, traj.clean[:, run], 'k', lw=1.0, label='clean')
    axes[2].set_ylabel('intensity (V)')
    axes[2].set_xlabel('time (s)')
    for ax in (axes[0], axes[2]):
        ax.legend(fontsize=8, loc='upper right')
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[0].set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def plot_acquisition(results: dict, *, level: int = 0, title: str) -> 'Figure':
    """Plot the acquisition-time histograms of record() (one noise level), one step line each."""
    from matplotlib.figure import Figure  # here: 0.7 s to import
    fig = Figure(figsize=(7.5, 4.5))
    ax = fig.add_subplot()
    for name, entry in results.items():
        hist = entry['acquisition_s']['histogram'][level]
        edges = np.asarray(hist['edges_s'])
        counts = np.asarray(hist['counts'])
        runs = counts.sum() + hist['censored']
        if not runs:
            continue
        ax.stairs(counts / runs, edges, lw=1.3,
                  label=f'{name} ({hist["censored"]} of {runs} runs not acquired)')
    ax.set_xlabel('acquisition time: |phi| within 15 deg, held 1 s (s)')
    ax.set_ylabel('fraction of runs per 0.25 s bin')
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc='upper right')
    fig.tight_layout()
    return fig


__all__ = ['plot_acquisition', 'plot_pat_run', 'ACQUIRED_WITHIN', 'angle_metrics', 'build_pat',
           'dark_steps', 'ekf_settings',
           'empty_record',
           'evaluate', 'join_metrics', 'metrics',
           'MIN_NOISE', 'PAT_ALGORITHMS', 'record', 'Recorded', 'STATES']
