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
The search for the maximum likelihood (tskf_ros.core.noise_search, noise_fit.fit).

Its stopping rule: the fit ends within a small fraction of a standard error of the
maximum that a search stopped by far stricter tolerances finds (the previous settings:
L-BFGS-B ftol 1e-13, then Nelder-Mead to 1e-10), on data with a known Q and R.
"""

import numpy as np
import pytest
import scipy.optimize

from tskf_ros.core import noise_fit
from tskf_ros.core.linear_models import LinearModel
from tskf_ros.core.noise_fit import fit, negative_log_likelihood, StepRecord, with_noise
from tskf_ros.core.noise_search import data_scale, LOG_L_TOLERANCE, NoiseParameters

# how close (in standard errors) the fit must come to the strict search's maximum
WITHIN_SE = 0.1


def strict_maximum(model, segments, par, theta):
    """Return the maximum of log L found from theta with strict tolerances (the reference)."""
    def f(t):
        Q, R = par.matrices(t, model.Q, model.R)
        return negative_log_likelihood(with_noise(model, Q, R), 'euler', segments)
    res = scipy.optimize.minimize(f, theta, method='L-BFGS-B',
                                  options={'ftol': 1e-15, 'gtol': 1e-10, 'maxiter': 1000})
    nm = scipy.optimize.minimize(f, res.x, method='Nelder-Mead',
                                 options={'xatol': 1e-9, 'fatol': 1e-10, 'maxiter': 4000})
    return (nm.x, nm.fun) if nm.fun <= res.fun else (res.x, res.fun)


def scalar_trace(n, seed, q, r, a=-0.1):
    """Return a scalar model (Q = R = 1: the start) and n steps at 1 s with 10 % gaps."""
    rng = np.random.default_rng(seed)
    mu = np.where(rng.random(n) < 0.1, rng.integers(2, 7, n), 1).astype(float)
    w, v = rng.standard_normal(n), rng.standard_normal(n)
    x, y = rng.standard_normal(), np.empty(n)
    for k in range(n):
        y[k] = x + np.sqrt(r / mu[k]) * v[k]
        x = (1.0 + mu[k] * a) * x + np.sqrt(mu[k] * q) * w[k]
    model = LinearModel('sim', A=np.array([[a]]), C=np.eye(1), Q=np.eye(1), R=np.eye(1),
                        x0=np.zeros(1), P0=np.eye(1))
    return model, [[StepRecord(float(m), np.array([yk])) for m, yk in zip(mu, y)]]


@pytest.mark.parametrize('q, r, seed', [(0.04, 0.25, 1), (1e-3, 4.0, 2), (2.0, 0.01, 3)])
def test_the_fit_stops_within_a_tenth_of_a_standard_error_of_the_maximum(monkeypatch, q, r,
                                                                         seed):
    # the coarse search over the first 500 of the 3000 measurements (its prefix is used)
    monkeypatch.setattr(noise_fit, 'COARSE_STEPS', 500)
    model, segments = scalar_trace(3000, seed, q, r)
    res = fit(model, 'euler', segments)
    par = NoiseParameters(1, 1)
    best, best_nll = strict_maximum(model, segments, par, res.theta)
    # the strict search finds the fit's maximum again, not another one
    assert -best_nll - res.log_likelihood <= LOG_L_TOLERANCE
    # the parameters the data determine (a standard error of the log below 1, those
    # tskf_fit_noise writes) within WITHIN_SE of their standard errors; on a plateau (Q
    # at q = 1e-3, r = 4: se(log q) > 100) the two searches stop anywhere along it
    z = (res.theta - best) / res.theta_stderr
    determined = res.theta_stderr < 1.0
    assert determined.any()
    assert np.all(np.abs(z[determined]) <= WITHIN_SE), z
    if determined.all():
        d = res.theta - best
        assert float(d @ np.linalg.solve(res.covariance_log, d)) <= WITHIN_SE ** 2
    # and the truth within 4 standard errors (the MLE is asymptotically normal)
    assert np.all(np.abs(res.theta - np.log([q, r])) <= 4 * res.theta_stderr)


def test_the_data_scale_is_the_medians_of_the_differences_in_memory():
    rng = np.random.default_rng(4)
    model = LinearModel('two', A=np.array([[-0.2, 1.0], [0.0, -0.5]]), C=np.eye(2),
                        Q=np.diag([0.03, 0.2]), R=np.diag([0.5, 2.0]), x0=np.zeros(2),
                        P0=np.eye(2))
    mu = rng.uniform(0.5, 1.5, 5000)
    ys = rng.standard_normal((5000, 2)) * np.exp2(rng.uniform(-10, 10, (5000, 1)))
    kept = rng.random(5000) >= 0.1
    steps = [StepRecord(m, y if keep else None) for m, y, keep in zip(mu, ys, kept)]
    trace = [steps[:1000], steps[1000:2500], steps[2500:]]
    par = NoiseParameters(2, 2)
    theta0 = par.start(model.Q, model.R)
    dys, dts = [], []
    for a, b in ((0, 1000), (1000, 2500), (2500, 5000)):
        t = np.concatenate([[0.0], np.cumsum(mu[a:b])])[:-1][kept[a:b]]
        dt, dy = np.diff(t), np.diff(ys[a:b][kept[a:b]], axis=0)
        dys.append(dy[dt > 0])
        dts.append(dt[dt > 0])
    v = np.median(np.square(np.concatenate(dys)), axis=0) / 0.455
    dt = float(np.median(np.concatenate(dts)))
    want = np.log(np.concatenate([np.full(2, np.mean(v) / dt), v * dt / 2.0]))
    # C G = I: |(C G)_j|^2 = 1
    np.testing.assert_allclose(data_scale(model, trace, par, theta0), want, rtol=1e-12)
