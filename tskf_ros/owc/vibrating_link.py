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
The vibration-induced intermittent OWC link of Cai et al. Section IV-A/B, simulated.

What is simulated (Cai et al., Section IV-A, Fig. 3 and Fig. 4):

- A laser on a vibration table driven by a random signal at f = 2 Hz.  Here the signal is a
  2 Hz carrier whose phase diffuses (a Brownian phase with rate `phase_diffusion`), so that
  samples taken at 1 Hz are not locked to the carrier.
- The amplitude follows the controller's "gain" knob, turned at random: turns arrive as a
  Poisson process of rate `knob_rate`, each a N(0, knob_step^2) increment, and the knob is
  reflected into [knob_min, knob_max] (folding the free random walk gives exactly that).
- The laser moves "from the origin to the right" (Fig. 4), so the relative angle is

      theta(t) = rest_angle + g(t) (1 - cos(2 pi f t + phi(t))) / 2,   in [rest, rest + g].

- The received power follows the angle-to-power curve of Fig. 5, `power_curve`:
  flat near the peak (P_max = 270 mW at theta = 0) up to 0.4141 rad, the linear fit
  eq. (2) P = -637.35 theta + 511.97 on [0.4141, 0.6729], a slow tail that reaches 0 at
  1.51 rad, and 0 beyond.  The pieces are quadratics joined continuously to eq. (2).
- The power meter adds N(0, noise_std^2) while light reaches the detector and reads 0
  when none does.  A reading at or below zero is invalid (Section IV-C: a signal
  interruption, the time jumps J of T_d).
- Optional blockages on top (fish, bubbles): Bernoulli drops with probability p, or a
  Gilbert-Elliott channel (Markov states good/bad with P(good -> bad) = p_gb,
  P(bad -> good) = p_bg per sample and a loss probability in each state).

Every random stream comes from `np.random.default_rng(seed)` (one spawned child per
stream, one draw per sample), so the same parameters and seed give the same samples
however they are requested: `OwcLink.generate(n)` in one call or n calls of one.
"""

from dataclasses import dataclass
from typing import Optional

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tskf_ros.core.dropouts import Dropouts, gilbert_elliott_states
from tskf_ros.core.linear_models import OWC_LINEAR_RANGE, OWC_OFFSET, OWC_SLOPE

P_MAX = 270.0             # mW at theta = 0 (Section IV-B)
THETA_ZERO = 1.51         # rad: Fig. 5 ends at 1.51 rad with the power at 0


class OwcLinkError(ValueError):
    """Parameters that do not describe a link that can be simulated."""


def linear_power(theta: ArrayLike) -> NDArray[np.float64]:
    """Cai et al. eq. (2): P = -637.35 theta + 511.97 (mW)."""
    return OWC_SLOPE * np.asarray(theta, dtype=float) + OWC_OFFSET


def power_curve(theta: ArrayLike) -> NDArray[np.float64]:
    """
    Received power (mW) at relative angle theta (rad): the shape of Cai et al. Fig. 5.

    Continuous, even in theta, non-increasing in |theta|, at most P_MAX and zero beyond
    THETA_ZERO; equal to eq. (2) on the fitted range [0.4141, 0.6729].
    """
    a = np.abs(np.asarray(theta, dtype=float))
    lo, hi = OWC_LINEAR_RANGE
    p_lo, p_hi = float(linear_power(lo)), float(linear_power(hi))
    # flat top: P_max - (P_max - P(lo)) (theta / lo)^2 on [0, lo]
    top = P_MAX - (P_MAX - p_lo) * (a / lo) ** 2
    # slow tail: P(hi) ((theta_zero - theta) / (theta_zero - hi))^2 on [hi, theta_zero]
    tail = p_hi * (np.clip(THETA_ZERO - a, 0.0, None) / (THETA_ZERO - hi)) ** 2
    return np.where(a <= lo, top, np.where(a <= hi, linear_power(a), tail))


@dataclass(frozen=True)
class OwcLinkConfig(Dropouts):
    """Parameters of the simulated link; units are s, Hz, rad and mW (blockages first)."""

    rate: float = 1.0                   # samples per second (the power meter, 1 Hz in IV-C)
    seed: int = 0
    vibration_frequency: float = 2.0    # Hz (Section IV-A)
    phase_diffusion: float = 4.0        # rad^2 / s of the carrier's Brownian phase
    rest_angle: float = 0.4141          # rad: theta with the table at rest
    knob_min: float = 0.0               # rad: vibration amplitude range of the gain knob
    knob_max: float = 1.2
    knob_initial: float = 0.3
    knob_rate: float = 0.2              # knob turns per second (Poisson)
    knob_step: float = 0.3              # rad: standard deviation of one turn
    noise_std: float = 10.0             # mW: v ~ N(0, 100) of system (3)

    def __post_init__(self) -> None:
        """Check every parameter; raise OwcLinkError with the reason."""
        for name in ('rate', 'vibration_frequency', 'phase_diffusion', 'rest_angle',
                     'knob_min', 'knob_max', 'knob_initial', 'knob_rate', 'knob_step',
                     'noise_std'):
            value = getattr(self, name)
            if not np.isfinite(value):
                raise OwcLinkError(f'{name} must be finite, got {value}')
        if not self.rate > 0:
            raise OwcLinkError(f'rate must be > 0 Hz, got {self.rate}')
        for name in ('vibration_frequency', 'phase_diffusion', 'knob_min', 'knob_rate',
                     'knob_step', 'noise_std'):
            if getattr(self, name) < 0:
                raise OwcLinkError(f'{name} must be >= 0, got {getattr(self, name)}')
        if not self.knob_min <= self.knob_initial <= self.knob_max:
            raise OwcLinkError(f'knob_initial {self.knob_initial} is outside '
                               f'[knob_min, knob_max] = [{self.knob_min}, {self.knob_max}]')
        self.check_dropouts(OwcLinkError)


@dataclass(frozen=True)
class Samples:
    """N consecutive samples of the link (arrays of length N)."""

    index: np.ndarray        # sample number k; the sample time is k / rate
    t: np.ndarray            # s since the start
    theta: np.ndarray        # rad, the true relative angle
    knob: np.ndarray         # rad, the vibration amplitude g
    power: np.ndarray        # mW, the noise-free received power P(theta)
    reading: np.ndarray      # mW, what the power meter reads
    blocked: np.ndarray      # bool: lost to a blockage (never reaches the receiver)
    bad_state: np.ndarray    # bool: Gilbert-Elliott channel in the bad state

    @property
    def valid(self) -> np.ndarray:
        """Return reading > 0 (Section IV-C: at or below zero is an interruption)."""
        return self.reading > 0

    def __len__(self) -> int:
        """Return the number of samples."""
        return self.index.size


def fold(w: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Reflect a free walk into [lo, hi] (a reflected random walk is a folded free one)."""
    span = hi - lo
    if span <= 0:
        return np.full_like(np.asarray(w, dtype=float), lo)
    r = np.mod(np.asarray(w, dtype=float) - lo, 2 * span)
    return lo + np.where(r > span, 2 * span - r, r)


class OwcLink:
    """A seeded, resumable stream of link samples; `generate(n)` returns the next n."""

    def __init__(self, config: OwcLinkConfig) -> None:
        self.config = config
        seq = np.random.SeedSequence(config.seed)
        (self._rng_phase0, self._rng_knob_count, self._rng_knob_step, self._rng_phase,
         self._rng_noise, self._rng_drop, self._rng_channel) = (
            np.random.default_rng(s) for s in seq.spawn(7))
        self._k = 0
        self._walk = config.knob_initial
        self._phase = float(self._rng_phase0.uniform(0.0, 2 * np.pi))
        bad0 = config.ge_p_gb / max(config.ge_p_gb + config.ge_p_bg, 1e-300)
        self._bad = bool(self._rng_phase0.random() < bad0)

    @property
    def count(self) -> int:
        """Return the number of samples generated so far."""
        return self._k

    def generate(self, n: int) -> Samples:
        """Return the next n samples (vectorised; one draw per sample from each stream)."""
        c = self.config
        n = int(n)
        if n < 0:
            raise OwcLinkError(f'n must be >= 0, got {n}')
        dt = 1.0 / c.rate
        k = self._k + np.arange(n)
        t = k * dt
        # gain knob: Poisson(knob_rate dt) turns per sample, each N(0, knob_step^2), reflected
        turns = self._rng_knob_count.poisson(c.knob_rate * dt, n)
        steps = np.sqrt(turns) * c.knob_step * self._rng_knob_step.standard_normal(n)
        # accumulate from the carried state so that any chunking gives the same floats
        walk = np.cumsum(np.concatenate([[self._walk], steps]))[1:]
        knob = fold(walk, c.knob_min, c.knob_max)
        # 2 Hz carrier with a Brownian phase: phi_k = phi_{k-1} + N(0, D dt)
        dphi = np.sqrt(c.phase_diffusion * dt) * self._rng_phase.standard_normal(n)
        phase = np.cumsum(np.concatenate([[self._phase], dphi]))[1:]
        # theta = rest + g (1 - cos(2 pi f t + phi)) / 2  (Fig. 4: from the origin rightwards)
        carrier = 2 * np.pi * c.vibration_frequency * t + phase
        theta = c.rest_angle + knob * (1 - np.cos(carrier)) / 2
        power = power_curve(theta)
        noise = c.noise_std * self._rng_noise.standard_normal(n)
        # the meter reads noise only while light reaches it, 0 when none does
        reading = np.where(power > 0, power + noise, 0.0)
        u_drop = self._rng_drop.random(n)
        u_switch = self._rng_channel.random(n)
        bad = self._channel_states(u_switch)
        if c.blockage == 'bernoulli':
            blocked = u_drop < c.drop_probability
        elif c.blockage == 'gilbert_elliott':
            blocked = u_drop < np.where(bad, c.ge_loss_bad, c.ge_loss_good)
        else:
            blocked = np.zeros(n, dtype=bool)
        if n:
            self._walk = float(walk[-1])
            self._phase = float(phase[-1])
        self._k += n
        return Samples(k, t, theta, knob, power, reading, blocked, bad)

    def _channel_states(self, u: np.ndarray) -> np.ndarray:
        """Gilbert-Elliott states of the next samples; u[k] < p decides the switch after k."""
        c = self.config
        bad, self._bad = gilbert_elliott_states(u, c.ge_p_gb, c.ge_p_bg, self._bad)
        return bad


def simulate_link(config: OwcLinkConfig, n: int, *, start: Optional[int] = None) -> Samples:
    """Generate n samples of a fresh link (optionally skipping the first `start`)."""
    link = OwcLink(config)
    if start:
        link.generate(start)
    return link.generate(n)
