"""
The drogue sample bag through the estimator node's filter, against drogue.py's own run.

The node runs the time-scale filter on the position fixes alone: it has no input topic,
so the acceleration u that drogue.py's switching filter feeds through B is missing, and
a dive is a constant-velocity jump.  The velocity error after the first dive is therefore
about 30 times drogue.py's (0.252 against 0.0076 m/s for seed 2013).  Against
drogue.py's switching filter on the same fixes *without* u, which differs from the node
only by Table 3's R / mu weighting of the fix before a dive, it agrees to 1 % (seeds
1..30: within 0.5 % below to 2.9 % above), hence the 5 % tolerance.
"""

from pathlib import Path

import numpy as np
from rclpy.serialization import deserialize_message

from tskf_ros import irregular
from tskf_ros.bag.estimator_io import load_config
from tskf_ros.bag.offline import replay
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.samples import DROGUE_TRUTH, NS, START_S
from tskf_ros.bag.types import message_class
from tskf_ros.experiments import drogue
from tskf_ros.nodes import conversions
from tskf_ros.tskf import exact_input_matrix, van_loan

REPO = Path(__file__).resolve().parent.parent
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
        elif m.topic == '/drogue/acceleration':
            u.append(msg.linear_acceleration.x)
        elif m.topic == '/drogue/truth':
            assert tuple(msg.name) == DROGUE_TRUTH
            truth.append(list(msg.position))
    return fixes, np.array(u), np.array(truth)


def _rms(e):
    return float(np.sqrt(np.mean(np.square(e))))


def test_drogue_config_is_drogue_py_model():
    config = load_config(PARAMS)
    est, cfg = config.estimator, drogue.DrogueConfig()
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
    assert res.samples == len(fixes) and res.statuses == {'accepted': len(fixes)}
    node = {_index(s): x[1] for s, x, _ in (
        conversions.msg_to_estimate(msg, 2) for topic, _, msg in res.outputs
        if topic == '/estimate/corrected')}
    k0 = run.observable_from()
    ks = [k for k in sorted(node) if k >= k0]
    # every fix after the first dive but the last (its mu is not known yet)
    assert ks == [k for k in sorted(fixes) if k >= k0][:-1]
    node_rms = _rms([node[k] - run.truth.x[k, 1] for k in ks])

    # drogue.py's switching filter without the input: the node's model less R / mu
    m = drogue.model_matrices(run.cfg)
    no_input = irregular.run_switching(
        m['A'], m['C'], Q=m['Q'], R=m['R'], x0=[run.y[0, 0], 0.0],
        P0=np.diag([run.cfg.gps_sd ** 2, 0.5 ** 2]), y=run.y, B=m['B'], u=np.zeros_like(u))
    no_input_rms = _rms(no_input.x_post[ks, 1] - run.truth.x[ks, 1])
    assert abs(node_rms / no_input_rms - 1) < 0.05, (node_rms, no_input_rms)
    assert abs(node_rms - 0.2520) < 1e-3

    # drogue.py's own run (with u) is ~30 times better: the node has no input topic
    own = run.rms()['drogue_velocity']
    own_at_fixes = _rms(run.est.x_post[ks, 1] - run.truth.x[ks, 1])
    assert own < 0.02 and own_at_fixes < 0.01
    assert node_rms > 10 * own
