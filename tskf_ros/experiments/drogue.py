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

"""
One drogue of Fang & de Callafon Section IV: flow velocity from irregular position fixes.

    m d'' = c (v_d(z) - d') |v_d(z) - d'|                                       eq. (26)
    x_{k+1} = [[1, T], [0, 1]] x_k + [T^2 / 2, T]^T u_k + w_k,  y_{t_l} = [1, 0] x_{t_l} + v
    v_d = x_2 + sign(u) sqrt(|u| m / c)                                  inverse of eq. (27)

with the switching Kalman filter of eqs. (13)-(17) on the double integrator above.
"""

import argparse
import bisect
from dataclasses import asdict, dataclass
import math
from pathlib import Path
import sys
import time
from typing import Optional, Sequence

import numpy as np

from tskf_ros.core import irregular
from tskf_ros.experiments import arguments
from tskf_ros.experiments.output import save_results


# the longest simulation the command line runs (25 times the paper's 4 h)
MAX_HOURS = 100.0


@dataclass(frozen=True)
class DrogueConfig:
    """Everything the simulation depends on (SI units)."""

    T: float = 5.0                      # s, sampling period of acceleration and depth
    duration: float = 4 * 3600.0        # s
    drag: float = 10.0                  # c / m in eq. (26), 1/m
    accel_sd: float = 1e-4              # m/s^2, accelerometer noise (white, per sample)
    gps_sd: float = 3.0                 # m, position fix at the surface
    model_sd: float = 2e-5              # m/s^2, extra input noise in the filter's Q (ZOH error)
    surface_samples: tuple = (1, 3)     # fixes per surfacing, drawn uniformly
    dive_minutes: tuple = (8.0, 40.0)   # dive durations, drawn uniformly
    dive_depth: tuple = (20.0, 80.0)    # m, dive depths, drawn uniformly
    substeps: int = 10                  # RK4 steps per sample for the truth
    seed: int = 6


def flow_velocity(z: np.ndarray) -> np.ndarray:
    """Along-front velocity v_d(z) in m/s at depth z >= 0 (m): a surface jet with ripples."""
    z = np.asarray(z, dtype=float)
    return 0.05 + 0.40 * np.exp(-z / 20.0) + 0.02 * np.sin(2 * np.pi * z / 16.0)


def _flow(z: float) -> float:
    """flow_velocity for one float (the truth integration calls it 10^5 times)."""
    return 0.05 + 0.40 * math.exp(-z / 20.0) + 0.02 * math.sin(2 * math.pi * z / 16.0)


@dataclass(frozen=True)
class Dive:
    """A dive from start to end (s), reaching depth (m): z = depth sin^2(pi s / length)."""

    start: float
    end: float
    depth: float


def diving_pattern(cfg: DrogueConfig, rng: np.random.Generator) -> tuple[list[Dive], np.ndarray]:
    """Draw an irregular diving pattern; return the dives and gamma_k (at the surface)."""
    N = int(round(cfg.duration / cfg.T)) + 1
    gamma = np.zeros(N, dtype=bool)
    dives: list[Dive] = []
    k = 0
    while k < N:
        n_fix = int(rng.integers(cfg.surface_samples[0], cfg.surface_samples[1] + 1))
        gamma[k:k + n_fix] = True
        k += n_fix - 1
        steps = int(round(rng.uniform(*cfg.dive_minutes) * 60.0 / cfg.T))
        dives.append(Dive(k * cfg.T, (k + steps) * cfg.T, float(rng.uniform(*cfg.dive_depth))))
        k += steps
    return dives, gamma


def depth_at(t: float, dives: Sequence[Dive], starts: Optional[Sequence[float]] = None
             ) -> float:
    """Return the depth z(t) (m): 0 at the surface; starts = the dives' start times."""
    if starts is None:
        starts = [d.start for d in dives]
    i = bisect.bisect_right(starts, t) - 1
    if i >= 0 and dives[i].start < t < dives[i].end:
        d = dives[i]
        return d.depth * math.sin(math.pi * (t - d.start) / (d.end - d.start)) ** 2
    return 0.0


@dataclass
class Truth:
    """The simulated drogue at the sampling instants k T."""

    t: np.ndarray
    z: np.ndarray           # depth
    v_flow: np.ndarray      # v_d(z(t))
    x: np.ndarray           # (N, 2): displacement d and velocity d'
    accel: np.ndarray       # d'' from eq. (26)
    gamma: np.ndarray       # position fix available


def simulate_drogue(cfg: DrogueConfig, rng: np.random.Generator) -> Truth:
    """Integrate eq. (26) with RK4 (cfg.substeps per sample) along a drawn diving pattern."""
    dives, gamma = diving_pattern(cfg, rng)
    N = gamma.size
    h = cfg.T / cfg.substeps

    starts = [d.start for d in dives]

    def accel(t: float, v: float) -> float:
        # eq. (26): d'' = (c / m) (v_d(z) - d') |v_d(z) - d'|
        e = _flow(depth_at(t, dives, starts)) - v
        return cfg.drag * e * abs(e)

    t = np.arange(N) * cfg.T
    x = np.zeros((N, 2))
    a = np.zeros(N)
    d, v = 0.0, float(flow_velocity(0.0))
    for k in range(N):
        x[k] = d, v
        a[k] = accel(t[k], v)
        if k == N - 1:
            break
        s = t[k]
        for _ in range(cfg.substeps):
            k1v = accel(s, v)
            k2v = accel(s + h / 2, v + h / 2 * k1v)
            k3v = accel(s + h / 2, v + h / 2 * k2v)
            k4v = accel(s + h, v + h * k3v)
            d += h / 6 * (v + 2 * (v + h / 2 * k1v) + 2 * (v + h / 2 * k2v) + (v + h * k3v))
            v += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
            s += h
    z = np.array([depth_at(s, dives, starts) for s in t])
    return Truth(t, z, flow_velocity(z), x, a, gamma)


def model_matrices(cfg: DrogueConfig) -> dict:
    """Return the discrete model of Section IV: A, B, C and the filter's Q, R."""
    T = cfg.T
    A = np.array([[1.0, T], [0.0, 1.0]])
    B = np.array([[T * T / 2], [T]])
    # the accelerometer noise enters through B like the input; model_sd covers the ZOH error
    Q = (cfg.accel_sd ** 2 + cfg.model_sd ** 2) * (B @ B.T)
    return {'A': A, 'B': B, 'C': np.array([[1.0, 0.0]]), 'Q': Q,
            'R': np.array([[cfg.gps_sd ** 2]])}


def flow_from_state(velocity: np.ndarray, u: np.ndarray, drag: float) -> np.ndarray:
    """Inverse of eq. (27): v_d = d' + sign(u) sqrt(|u| m / c)."""
    return velocity + np.sign(u) * np.sqrt(np.abs(u) / drag)


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e ** 2)))


@dataclass
class DrogueRun:
    """Truth, measurements and estimates of one run."""

    cfg: DrogueConfig
    truth: Truth
    u: np.ndarray           # measured acceleration
    y: np.ndarray           # (N, 1) position fixes, NaN under water
    est: irregular.FilterHistory
    v_flow_hat: np.ndarray

    def rms(self, start: Optional[int] = None) -> dict:
        """RMS errors from sample `start` on (default: `observable_from`); start=0: all."""
        if start is None:
            start = self.observable_from()
        s = slice(start, None)
        e_v = self.est.x_post[s, 1] - self.truth.x[s, 1]
        e_f = self.v_flow_hat[s] - self.truth.v_flow[s]
        e_n = self.est.x_post[s, 1] - self.truth.v_flow[s]
        e_d = self.est.x_post[s, 0] - self.truth.x[s, 0]
        return {'from_sample': start,
                'drogue_velocity': _rms(e_v),
                'flow_velocity': _rms(e_f),
                'flow_velocity_without_inverse_27': _rms(e_n),
                'displacement': _rms(e_d),
                'filter_velocity_sd': float(np.sqrt(np.mean(self.est.P_post[s, 1, 1])))}

    def observable_from(self) -> int:
        """
        Return the first fix after the first dive.

        Before it the filter has fixes only from the first surfacing (seconds apart, 3 m
        each), so the velocity is the prior's; this is when it becomes known.
        """
        fixes = np.flatnonzero(self.truth.gamma)
        after_dive = np.flatnonzero(np.diff(fixes) > 1)
        return int(fixes[after_dive[0] + 1]) if after_dive.size else int(fixes[-1])

    def intervals(self) -> list[int]:
        """Return the set T of sampling intervals, in samples."""
        return sorted({int(k) for k in np.diff(np.flatnonzero(self.truth.gamma))})


def run(cfg: DrogueConfig = DrogueConfig()) -> DrogueRun:
    """Simulate one drogue and run the switching filter on it (seeded by cfg.seed)."""
    rng = np.random.default_rng(cfg.seed)
    truth = simulate_drogue(cfg, rng)
    N = truth.t.size
    u = truth.accel + cfg.accel_sd * rng.standard_normal(N)
    y = np.full((N, 1), np.nan)
    fixes = truth.gamma
    y[fixes, 0] = truth.x[fixes, 0] + cfg.gps_sd * rng.standard_normal(int(fixes.sum()))
    m = model_matrices(cfg)
    # no prior knowledge of the flow (Section IV): velocity 0 +- 0.5 m/s
    x0 = [y[0, 0] if fixes[0] else 0.0, 0.0]
    P0 = np.diag([cfg.gps_sd ** 2, 0.5 ** 2])
    est = irregular.run_switching(m['A'], m['C'], Q=m['Q'], R=m['R'], x0=x0, P0=P0, y=y,
                                  B=m['B'], u=u)
    return DrogueRun(cfg, truth, u, y, est, flow_from_state(est.x_post[:, 1], u, cfg.drag))


def plot(r: DrogueRun):
    """Fig. 3 and Fig. 4 in one figure: states, errors with 2 sigma, flow and depth."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    t = r.truth.t / 3600.0
    fix = r.truth.gamma
    k0 = r.observable_from()
    fig, ax = plt.subplots(3, 2, figsize=(12, 10), sharex=True)
    for col, (i, name, unit) in enumerate(((0, 'x_1 = d', 'm'), (1, "x_2 = d'", 'm/s'))):
        a = ax[0, col] if col == 0 else ax[1, 0]
        a.plot(t, r.truth.x[:, i], 'k-', lw=1, label='true')
        a.plot(t, r.est.x_post[:, i], 'C1--', lw=1, label='estimated')
        a.plot(t[fix], r.truth.x[fix, i], 'o', mfc='none', ms=4, color='C0',
               label='sampling instant')
        a.set_ylabel(f'{name} ({unit})')
        a.legend(loc='best', fontsize=8)
        b = ax[0, 1] if col == 0 else ax[1, 1]
        err = r.est.x_post[:, i] - r.truth.x[:, i]
        sd = np.sqrt(r.est.P_post[:, i, i])
        b.fill_between(t, -2 * sd, 2 * sd, color='C1', alpha=0.25, label='+-2 sigma (filter)')
        b.plot(t, err, 'C1-', lw=0.8, label='error')
        b.axvspan(t[0], t[k0], color='0.85', label='before the 2nd surfacing (clipped)')
        lim = 1.2 * max(np.max(2 * sd[k0:]), np.max(np.abs(err[k0:])))
        b.set_ylim(-lim, lim)
        b.set_ylabel(f'error in {name} ({unit})')
        b.legend(loc='best', fontsize=8)
    a = ax[2, 0]
    a.plot(t, r.truth.v_flow, 'k-', lw=1, label='true v_d(z)')
    a.plot(t, r.v_flow_hat, 'C1-', lw=0.6, alpha=0.8, label='estimated (inverse of (27))')
    a.set_ylabel('along-front velocity (m/s)')
    a.legend(loc='best', fontsize=8)
    a = ax[2, 1]
    a.plot(t, r.truth.z, 'k-', lw=1)
    a.plot(t[fix], r.truth.z[fix], 'o', mfc='none', ms=4, color='C0')
    a.invert_yaxis()
    a.set_ylabel('depth (m)')
    for a in ax[2]:
        a.set_xlabel('time (h)')
    rms = r.rms()
    fig.suptitle(f'One drogue, switching Kalman filter (Fang & de Callafon Sec. IV): RMS '
                 f'error after the first dive: drogue velocity {rms["drogue_velocity"]:.4f} '
                 f'm/s, flow {rms["flow_velocity"]:.4f} m/s')
    fig.tight_layout()
    return fig


def summary(r: DrogueRun, seconds: float) -> dict:
    """Return the JSON summary: config, RMS errors, intervals and the Section III checks."""
    m = model_matrices(r.cfg)
    T = r.intervals()
    check = irregular.theorem1(m['A'], m['C'], T)
    return {
        'paper': 'Fang & de Callafon, CDC 2011, Section IV',
        'config': asdict(r.cfg),
        'samples': int(r.truth.t.size),
        'position_fixes': int(r.truth.gamma.sum()),
        'sampling_intervals': T,
        'rms': r.rms(),
        'rms_from_start': r.rms(0),
        'pathological_intervals': list(check.pathological),
        'degenerate_intervals': list(check.degenerate),
        'theorem1_stable': check.stable,
        'corollary1': irregular.corollary1(m['A']),
        'seconds': seconds,
    }


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the drogue example, print the RMS errors, write drogue.png and drogue.json."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--out', type=Path, required=True, help='output directory')
    parser.add_argument('--seed', type=arguments.seed, default=DrogueConfig.seed)
    parser.add_argument('--hours', type=arguments.number(0.0, MAX_HOURS, open_low=True),
                        default=DrogueConfig.duration / 3600.0,
                        help=f'simulated hours (default 4, at most {MAX_HOURS:g})')
    args = parser.parse_args(argv)
    start = time.perf_counter()
    try:
        r = run(DrogueConfig(seed=args.seed, duration=args.hours * 3600.0))
        data = summary(r, time.perf_counter() - start)
    except irregular.IrregularError as exc:     # e.g. too short for one sampling interval
        print(f'drogue: error: {exc}', file=sys.stderr)
        return 1
    rms = data['rms']
    print(f'drogue: {data["samples"]} samples, {data["position_fixes"]} position fixes, '
          f'intervals {data["sampling_intervals"][0]}..{data["sampling_intervals"][-1]}')
    print(f'RMS velocity error after the first dive (from t = {rms["from_sample"] * r.cfg.T:.0f} '
          f's): drogue {rms["drogue_velocity"]:.5f} m/s '
          f'(filter sd {rms["filter_velocity_sd"]:.5f}), flow {rms["flow_velocity"]:.5f} m/s, '
          f'displacement {rms["displacement"]:.3f} m')
    rms0 = data['rms_from_start']
    print(f'RMS velocity error over the whole run: drogue {rms0["drogue_velocity"]:.5f} m/s, '
          f'flow {rms0["flow_velocity"]:.5f} m/s')
    print(f'Theorem 1: pathological {data["pathological_intervals"]}, degenerate '
          f'{data["degenerate_intervals"]}, stable: {data["theorem1_stable"]}')
    save_results(args.out, 'drogue', plot(r), data)
    return 0


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
