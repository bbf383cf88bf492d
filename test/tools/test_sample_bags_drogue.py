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
The drogue sample bag through the estimator node's filter, against drogue.py's own run.

The bag carries the measured acceleration u on /input every T = 5 s, so the node's
session splits each dive at the input stamps and integrates u over it (zero-order hold):
it is the time-scale filter stepped every T with y only at the fixes.  The offline
replay equals that filter run directly to 1e-9 (same arithmetic, other order of calls),
and its velocity RMS error at the fixes after the first dive is 0.00342 m/s (seed 2013),
against 0.252 m/s when u is left out (the old node without an input topic).  drogue.py's
switching filter with u gives 0.003422 at the same instants: the two differ only in
Table 3's weighting of a fix (R / mu with mu = T, the same 3 m; the corrected estimate
of the time-scale filter is that of the switching filter's update), so they agree to
about 0.1 %; a 2 % tolerance leaves room for platform rounding of the expm.
"""

from pathlib import Path

import numpy as np
import pytest
from rclpy.serialization import deserialize_message

from tskf_ros.bag.message_types import message_class
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.replay.loop import replay
from tskf_ros.bag.replay.topic_choice import InputError
from tskf_ros.core import irregular
from tskf_ros.core.transitions import exact_input_matrix, van_loan
from tskf_ros.experiments import drogue
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import load_config
from tskf_ros.tools.sample_bags import DROGUE_TRUTH, NS, START_S

REPO = Path(__file__).resolve().parents[2]
BAG = REPO / 'bags' / 'drogue'
PARAMS = REPO / 'config' / 'drogue_estimator.yaml'
SEED = 2013          # bags/README.md
T = drogue.DrogueConfig.T


def _index(stamp_ns):
    return int(round((stamp_ns - START_S * NS) / (T * NS)))


def _bag():
    """Return the fixes {k: y}, u (N,) and the truth (N, 4) of the drogue bag."""
    fixes, u, truth = {}, [], []
    for m in BagReader(BAG).messages():
        msg = deserialize_message(m.data, message_class(m.msgtype))
        if m.topic == '/received_power':
            stamp, y, _ = conversions.msg_to_power(msg)
            fixes[_index(stamp)] = y
        elif m.topic == '/input':
            stamp, uk = conversions.msg_to_input(msg, 1)
            assert _index(stamp) == len(u)
            u.append(uk[0])
        elif m.topic == '/drogue/truth':
            assert tuple(msg.name) == DROGUE_TRUTH
            truth.append(list(msg.position))
    return fixes, np.array(u), np.array(truth)


def _rms(e):
    return float(np.sqrt(np.mean(np.square(e))))


def test_drogue_config_is_drogue_py_model():
    config = load_config(PARAMS)
    est, cfg = config.session, drogue.DrogueConfig()
    assert not est.nonpositive_is_gap
    longest_dive = cfg.dive_minutes[1] * 60.0
    assert est.max_jump > longest_dive and est.max_gap < est.max_jump
    assert est.transition == 'exact' and est.period == cfg.T
    m, d = est.model, drogue.model_matrices(cfg)
    # the continuous model sampled at T is drogue.py's discrete one
    F, Qd = van_loan(m.A, m.G @ m.Q @ m.G.T, cfg.T)
    np.testing.assert_allclose(F, d['A'], atol=1e-12)
    np.testing.assert_allclose(exact_input_matrix(m.A, m.B, cfg.T), d['B'], atol=1e-12)
    # same velocity variance per step; R / mu at mu = T is the 3 m fix
    np.testing.assert_allclose(Qd[1, 1], d['Q'][1, 1], rtol=1e-9)
    np.testing.assert_allclose(m.R / cfg.T, d['R'], rtol=1e-12)


def test_offline_replay_of_the_drogue_bag_against_drogue_py():
    fixes, u, truth = _bag()
    run = drogue.run(drogue.DrogueConfig(seed=SEED))
    # the bag is drogue.py's run: same fixes, input and truth
    assert sorted(fixes) == np.flatnonzero(run.truth.gamma).tolist()
    np.testing.assert_array_equal([fixes[k] for k in sorted(fixes)], run.y[run.truth.gamma, 0])
    np.testing.assert_array_equal(u, run.u)
    np.testing.assert_array_equal(truth[:, :2], run.truth.x)

    res = replay(BAG, None, params_file=PARAMS, diagnostics=False)
    assert res.input_topic == '/input' and res.inputs == len(u)
    assert res.samples == len(fixes) and res.statuses == {'accepted': len(fixes)}
    assert res.input_statuses == {'accepted': len(u)}
    estimates = {kind: {_index(e.stamp_ns): (e.x, e.P) for e in (
        conversions.msg_to_state_estimate(msg) for topic, _, msg in res.outputs
        if topic == f'/estimate/{kind}')} for kind in ('corrected', 'predicted')}
    node = {k: x[1] for k, (x, _) in estimates['corrected'].items()}
    k0 = run.observable_from()
    ks = [k for k in sorted(node) if k >= k0]
    # every fix after the first dive, the last too: the next input point gives its mu
    assert ks == [k for k in sorted(fixes) if k >= k0]
    node_rms = _rms([node[k] - run.truth.x[k, 1] for k in ks])

    # the time-scale filter stepped every T with u and the fixes: the node's run exactly
    config = load_config(PARAMS).session
    kf = config.model.make_filter(config.transition)
    assert sorted(estimates['predicted']) == list(range(len(u)))
    for k in range(len(u) - 1):
        step = kf.step(T, fixes.get(k), [u[k]])
        x, P = estimates['predicted'][k + 1]
        np.testing.assert_allclose(x, step.x_predicted, rtol=0, atol=1e-9)
        np.testing.assert_allclose(P, step.P_predicted, rtol=1e-9, atol=1e-12)
        if k in estimates['corrected']:
            x, P = estimates['corrected'][k]
            np.testing.assert_allclose(x, step.x_corrected, rtol=0, atol=1e-9)
    assert abs(node_rms - 0.003418) < 1e-5, node_rms

    # drogue.py's switching filter with u at the same instants: the same to ~0.1 %
    own_at_fixes = _rms(run.est.x_post[ks, 1] - run.truth.x[ks, 1])
    assert abs(node_rms / own_at_fixes - 1) < 0.02, (node_rms, own_at_fixes)
    assert run.rms()['drogue_velocity'] < 0.02

    # without u (the node before it had an input topic) the error is ~70 times larger
    m = drogue.model_matrices(run.cfg)
    no_input = irregular.run_switching(
        m['A'], m['C'], Q=m['Q'], R=m['R'], x0=[run.y[0, 0], 0.0],
        P0=np.diag([run.cfg.gps_sd ** 2, 0.5 ** 2]), y=run.y, B=m['B'], u=np.zeros_like(u))
    no_input_rms = _rms(no_input.x_post[ks, 1] - run.truth.x[ks, 1])
    assert no_input_rms > 50 * node_rms


def test_input_topic_must_exist_and_be_accel_stamped():
    with pytest.raises(InputError, match='no input topic /nope'):
        replay(BAG, None, params_file=PARAMS, input_topic='/nope')
    with pytest.raises(InputError, match='not geometry_msgs/msg/AccelStamped'):
        replay(BAG, None, params_file=PARAMS, input_topic='/drogue/truth')
