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
A scalar Kalman filter in textbook form, independent of the filter under test.

S = c^2 P + R_d, L = P c / S, x(t|t) = x + L (y - c x - d), P(t|t) in Joseph form, then
x(sigma) = F x(t|t), P(sigma) = F^2 P(t|t) + Q_d with F = 1 + mu a, Q_d = mu q (Euler) or
F = e^{a mu}, Q_d = q (F^2 - 1) / (2 a) (exact).
"""

import math

import pytest

from tskf_ros.owc.session import EstimatorConfig, EstimatorSession, model_from_flat

# a stable scalar model with an offset; readings of either sign are points
A, C, D, Q, R, X0, P0 = -0.3, 2.0, 5.0, 0.5, 0.2, 1.0, 0.5
MODEL = model_from_flat(A=[A], C=[C], D=[D], Q=[Q], R=[R], x0=[X0], P0=[P0])
REL = 1e-10                 # textbook form against Table 3: rounding only


class Reference:
    """The scalar Kalman filter of the model, textbook form, on plain floats."""

    def __init__(self, a=A, c=C, d=D, q=Q, r=R, x=X0, P=P0, transition='euler'):
        self.a, self.c, self.d, self.q, self.r = a, c, d, q, r
        self.x, self.P, self.transition = x, P, transition

    def transition_of(self, mu):
        """(F, Q_d) over mu: I + mu A, mu Q, or e^{a mu} and its integral."""
        if self.transition == 'euler':
            return 1.0 + mu * self.a, mu * self.q
        F = math.exp(self.a * mu)
        return F, self.q * (F * F - 1.0) / (2.0 * self.a)

    def step(self, mu, y, variance=0.0):
        """Correct at t with y (R_d = variance if > 0, else R / mu), predict sigma(t)."""
        c, P = self.c, self.P
        rd = variance if variance > 0 else self.r / mu
        S = c * c * P + rd
        L = P * c / S
        x_c = self.x + L * (y - c * self.x - self.d)
        P_c = (1.0 - L * c) ** 2 * P + L * L * rd
        F, Qd = self.transition_of(mu)
        self.x, self.P, self.corrected = F * x_c, F * F * P_c + Qd, (x_c, P_c)
        return x_c, P_c, self.x, self.P

    def gate_distance(self, y, period):
        """Mahalanobis distance of y at the predictor, with R / period."""
        return abs(y - self.c * self.x - self.d) / math.sqrt(
            self.c * self.c * self.P + self.r / period)


def scalar_session(**extra):
    """Return a session of MODEL (readings of either sign are points unless told)."""
    extra.setdefault('nonpositive_is_gap', False)
    return EstimatorSession(EstimatorConfig(MODEL, **extra))


def close(got, want):
    assert got == pytest.approx(want, rel=REL, abs=1e-300), (got, want)


def check_step(out, t, sigma, ref_values):
    """Check the outcome of an ordinary sample: corrected at t, predicted at sigma."""
    x_c, P_c, x_p, P_p = ref_values
    assert out.status == 'accepted', (out.reason, out.message)
    (corr, pred), (jump,) = out.estimates, out.jumps
    assert (corr.kind, corr.stamp_ns, pred.kind, pred.stamp_ns) == (
        'corrected', t, 'predicted', sigma)
    assert corr.x.shape == (1,) and corr.P.shape == (1, 1) and pred.P.shape == (1, 1)
    for got, want in ((corr.x[0], x_c), (corr.P[0, 0], P_c), (pred.x[0], x_p),
                      (pred.P[0, 0], P_p)):
        close(got, want)
    assert (jump.stamp_ns, jump.sigma_ns) == (t, sigma)
