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
The LED link of Solanki et al. Section V as a plant for live alignment: a seeded sample stream.

Eq. (25) one sample at a time: phi = base - bearing with bearing_{k+1} = bearing_k - beta dt
- w2, x1_{k+1} = |x1_k + w1|, and the photodiode of eq. (5)/(8), z_k = x1_k g(phi_k) + v_k;
the base follows position commands; optional dropouts (tskf_ros.core.dropouts).  What is
simulated and why: doc/design/alignment.md.
"""

from dataclasses import dataclass
import math
from typing import Optional

import numpy as np

from tskf_ros import led
from tskf_ros.core.dropouts import Dropouts, gilbert_elliott_states
from tskf_ros.led.alignment_session import AlignmentSession, AlignOutcome
from tskf_ros.led.intensity_model import FloatArray


class LedLinkError(ValueError):
    """Parameters that do not describe an LED link that can be simulated."""


@dataclass(frozen=True)
class LedLinkConfig(Dropouts):
    """Parameters of the simulated LED link; angles in degrees, intensities in volts."""

    beta: float = 1.2                 # deg/s: the transmitter's revolution (Fig. 8)
    dt: float = led.PAPER_DT          # s per sample (Section VI: about 50 ms per iteration)
    noise: float = 0.2                # V: standard deviation of v (R_sys = 0.04)
    max_intensity: float = led.MAX_INTENSITY     # V: x1 g at the peak of g
    phi0: float = 5.0                 # deg: angle of incidence at sample 0
    angle_noise: float = 0.1          # deg per sample: w2 of eq. (25), sqrt(Q_sys[2,2])
    intensity_walk: float = 0.05      # V per sample: w1 of eq. (25), sqrt(Q_sys[1,1])
    max_speed: float = 0.0            # deg/s the base turns at most; 0: any turn in a step
    units_per_degree: float = 0.0     # fit units of g per degree; 0: the tracking-zone unit
    seed: int = 0

    def __post_init__(self) -> None:
        """Check every parameter; raise LedLinkError with the reason."""
        for name in ('beta', 'dt', 'noise', 'max_intensity', 'phi0', 'angle_noise',
                     'intensity_walk', 'max_speed', 'units_per_degree'):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise LedLinkError(f'{name} must be finite, got {value}')
        if not self.dt > 0:
            raise LedLinkError(f'dt must be > 0 s, got {self.dt}')
        if not self.max_intensity > 0:
            raise LedLinkError(f'max_intensity must be > 0 V, got {self.max_intensity}')
        for name in ('noise', 'angle_noise', 'intensity_walk', 'max_speed',
                     'units_per_degree'):
            if getattr(self, name) < 0:
                raise LedLinkError(f'{name} must be >= 0, got {getattr(self, name)}')
        self.check_dropouts(LedLinkError)

    def response(self) -> led.IncidenceResponse:
        """Return g of eq. (4) in this link's unit (0: the tracking-zone unit)."""
        return led.IncidenceResponse(units_per_degree=self.units_per_degree or None)


@dataclass(frozen=True)
class LedSample:
    """One sample of the link: the truth and what the photodiode reads."""

    index: int          # sample number k; its time is k dt
    t: float            # s since sample 0
    phi: float          # deg: true angle of incidence, wrapped to [-180, 180)
    base: float         # deg: base angle
    bearing: float      # deg: transmitter bearing (phi = base - bearing)
    x1: float           # V: intensity factor
    clean: float        # V: x1 g(phi)
    reading: float      # V: clean + v
    blocked: bool       # lost to a dropout: never reaches the receiver


class LedLink:
    """A seeded, resumable LED link; `command` moves the base, `sample` returns the next one."""

    def __init__(self, config: LedLinkConfig) -> None:
        self.config = config
        self.g = config.response()
        seq = np.random.SeedSequence(config.seed)
        (self._rng_channel0, self._rng_w1, self._rng_w2, self._rng_v, self._rng_drop,
         self._rng_channel) = (np.random.default_rng(s) for s in seq.spawn(6))
        bad0 = config.ge_p_gb / max(config.ge_p_gb + config.ge_p_bg, 1e-300)
        self._bad = bool(self._rng_channel0.random() < bad0)
        self._k = 0
        self.base = 0.0
        self.target = 0.0
        self.bearing = -config.phi0
        self.x1 = config.max_intensity / self.g.peak
        # an obstruction in the beam (set at run time): no light, the photodiode reads v
        self.obstructed = False

    @property
    def count(self) -> int:
        """Return the number of samples taken so far."""
        return self._k

    @property
    def phi(self) -> float:
        """Return the angle of incidence now (deg, wrapped)."""
        return float(led.wrap_degrees(self.base - self.bearing))

    def command(self, angle: float) -> None:
        """Take a position command for the base (deg), as a position controller would."""
        angle = float(angle)
        if not math.isfinite(angle):
            raise LedLinkError(f'base command must be finite, got {angle}')
        self.target = angle

    def sample(self) -> LedSample:
        """Move the plant over one interval (not before sample 0), then take the next sample."""
        c = self.config
        if self._k > 0:
            self._advance()
        k = self._k
        v = self._rng_v.standard_normal() * c.noise
        u_drop = self._rng_drop.random()
        bad, self._bad = gilbert_elliott_states(
            np.array([self._rng_channel.random()]), c.ge_p_gb, c.ge_p_bg, self._bad)
        if c.blockage == 'bernoulli':
            blocked = u_drop < c.drop_probability
        elif c.blockage == 'gilbert_elliott':
            blocked = u_drop < (c.ge_loss_bad if bad[0] else c.ge_loss_good)
        else:
            blocked = False
        phi = self.phi
        # (5)/(8): z = x1 g(phi) + v; nothing of the light while the beam is obstructed
        clean = 0.0 if self.obstructed else float(self.x1 * self.g.g(phi))
        self._k += 1
        return LedSample(k, k * c.dt, phi, self.base, self.bearing, self.x1, clean, clean + v,
                         bool(blocked))

    def _advance(self) -> None:
        """One interval of eq. (25): beta dt + w2 on phi, x1 walks, the base turns."""
        c = self.config
        w1 = self._rng_w1.standard_normal() * c.intensity_walk
        w2 = self._rng_w2.standard_normal() * c.angle_noise
        self.bearing -= c.beta * c.dt + w2
        self.x1 = abs(self.x1 + w1)
        turn = self.target - self.base
        if c.max_speed > 0:
            limit = c.max_speed * c.dt
            turn = min(max(turn, -limit), limit)
        self.base += turn


def sample_offset_ns(k: int, dt: float) -> int:
    """Return the stamp of sample k relative to sample 0, in integer nanoseconds."""
    return int(round(k * dt * 1e9))


@dataclass
class LoopResult:
    """A closed-loop run: the link's samples and the session's outcomes (None: dropped)."""

    samples: list[LedSample]
    outcomes: list[Optional[AlignOutcome]]

    def phi(self) -> FloatArray:
        """Return the true angle of incidence per sample (deg)."""
        return np.array([s.phi for s in self.samples])

    def tracking(self, *, start: int = 0, angle: float = led.TRACKING_ANGLE) -> float:
        """Return the percentage of samples from `start` with |phi| <= angle (Section V)."""
        phi = self.phi()[start:]
        return 100.0 * float(np.mean(np.abs(phi) <= angle)) if phi.size else float('nan')


def closed_loop(link: LedLinkConfig, session: AlignmentSession, steps: int, *,
                start_ns: int = 1_000_000_000, base: Optional[float] = None) -> LoopResult:
    """
    Run `steps` samples of the link against an AlignmentSession, as the two nodes do.

    Sample k is stamped start_ns + k dt; a delivered sample goes to session.add, and the
    base command it returns (if any) is applied before the next sample.  This is the
    reference the node tests compare against.
    """
    plant = LedLink(link)
    if base is not None:
        plant.base = plant.target = float(base)
    samples: list[LedSample] = []
    outcomes: list[Optional[AlignOutcome]] = []
    for k in range(int(steps)):
        s = plant.sample()
        samples.append(s)
        if s.blocked:
            outcomes.append(None)
            continue
        out = session.add(start_ns + sample_offset_ns(k, link.dt), s.reading)
        outcomes.append(out)
        if out.command is not None:
            plant.command(out.command)
    return LoopResult(samples, outcomes)
