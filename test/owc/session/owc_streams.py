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

"""Streams for the estimator session's tests: Cai's OWC readings, and feeding them."""

import numpy as np

from tskf_ros.core.linear_models import owc
from tskf_ros.core.units import NS
from tskf_ros.owc.session import EstimatorConfig, EstimatorSession

T0 = 1_700_000_000 * NS
OWC = owc()
THETA = 0.5435                      # rad: the OWC model's x0, inside the linear range
# 1 Hz with gaps J = 3 (after 4) and J = 4 (after 12), and a dense stretch at 0.25 s
STAMPS = np.array([1, 2, 3, 4, 7, 8, 9, 10, 11, 12, 16, 16.25, 16.5, 16.75, 17, 18, 19, 20])


def power(theta):
    """Cai eq. (2): the noise-free reading at angle theta."""
    return float(OWC.C[0, 0] * theta + OWC.D[0])


def owc_session(**extra):
    """Return a session of the OWC model with the config's defaults but `extra`."""
    return EstimatorSession(EstimatorConfig(OWC, **extra))


def feed_seconds(session, seconds, theta=THETA, start=0.0, rng=None):
    """One reading after T0 at each of the seconds given (noise 10 mW, seeded)."""
    rng = rng or np.random.default_rng(0)
    return [session.add(T0 + int(round((start + t) * NS)),
                        power(theta) + 10.0 * rng.standard_normal())
            for t in seconds]


def measurements(model, t, seed=0):
    """Noisy measurements of a state near the model's x0 at the points t."""
    rng = np.random.default_rng(seed)
    x = model.x0 + 0.02 * rng.standard_normal((t.size, model.x0.size))
    y = x @ model.C.T + (0 if model.D is None else model.D)
    return y + np.sqrt(np.diag(model.R)) * rng.standard_normal(y.shape)


def feed(session, t, y):
    """Feed (t in s, y) in order; return the outcomes."""
    return [session.add(int(round(ti * NS)), yi) for ti, yi in zip(t, y)]


def collect(outcomes, kind, revised=False):
    """(stamps in s, states, covariances) of the estimates of one kind."""
    est = [e for o in outcomes for e in o.estimates if e.kind == kind and e.revised == revised]
    return np.array([e.stamp_ns / NS for e in est]), np.array([e.x for e in est]), \
        np.array([e.P for e in est])


def task(session, name, now_ns=None):
    """Return the status of one diagnostic task of the session (an update: it consumes)."""
    return next(s for s in session.diagnostics(now_ns=now_ns) if s.name == name)


def values(session, name='filter health', now_ns=None):
    """Return the key values of one diagnostic task of the session, as printed."""
    return task(session, name, now_ns).as_dict()
