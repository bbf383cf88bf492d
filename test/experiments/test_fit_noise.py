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
fit_noise: maximum likelihood of Q and R over the time-scale filter's innovations.

Bags are simulated here from the filter's own model with known Q and R, with gaps:
x(t_{k+1}) = (1 + mu_k a) x(t_k) + sqrt(mu_k q) w_k,  y(t_k) = x(t_k) + sqrt(r / mu_k) v_k,
mu_k = t_{k+1} - t_k (Bohner & Wintz's white noise over one point of measure mu).  The
likelihood is checked against a scalar Kalman filter written out in this file.
"""

import gc
import json
from pathlib import Path
import tempfile

import numpy as np
from open_files import open_files_in
import pytest
from rclpy.serialization import serialize_message
from stderr_lines import one_line
from tskf_ros.bag.writer import BagWriter
from tskf_ros.core import noise_fit, spill_rows
from tskf_ros.core.noise_fit import run_trace
from tskf_ros.experiments import fit_noise
from tskf_ros.experiments.bag_analysis import read_stream
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import load_config
from tskf_ros.owc.innovation_trace import Measurement, run_stream
from tskf_ros.owc.session import EstimatorSession

REPO = Path(__file__).resolve().parents[2]
A_TRUE, Q_TRUE, R_TRUE = -0.1, 0.04, 0.25
PARAMS = """/**/timescale_estimator:
  ros__parameters:
    model_name: sim
    state_names: [x]
    A: [-0.1]
    C: [1.0]
    D: [0.0]
    Q: [1.0]
    R: [1.0]
    x0: [0.0]
    P0: [1.0]
    nonpositive_is_gap: false
    max_gap: 10.0
"""


def simulate(path: Path, n: int, seed: int, q: float = Q_TRUE, r: float = R_TRUE,
             spikes: tuple = ()) -> tuple:
    """Write n samples at 1 s with 10% gaps of 2-6 s (y[k] = 1e300 for k in spikes)."""
    rng = np.random.default_rng(seed)
    dt = np.where(rng.random(n) < 0.1, rng.integers(2, 7, n), 1).astype(float)
    t = 1000.0 + np.concatenate([[0.0], np.cumsum(dt[:-1])])
    x = rng.normal(0.0, 1.0)
    ys = np.empty(n)
    for k in range(n):
        ys[k] = x + np.sqrt(r / dt[k]) * rng.standard_normal()
        x = (1.0 + dt[k] * A_TRUE) * x + np.sqrt(dt[k] * q) * rng.standard_normal()
    ys[list(spikes)] = 1e300
    write_samples(path, t, ys)
    return t, ys


def write_samples(path: Path, t: np.ndarray, ys: np.ndarray, tail: bytes = b'') -> None:
    """Write (t s, y) as Illuminance on /received_power, then the raw bytes `tail`."""
    with BagWriter(path) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for tk, yk in zip(t, ys):
            ns = int(round(tk * 1e9))
            w.write('/received_power', ns,
                    serialize_message(conversions.power_to_msg(ns, yk, 0.0)))
        if tail:
            w.write('/received_power', int(round(t[-1] * 1e9)) + 10**9, tail)


def scalar_log_likelihood(t: np.ndarray, y: np.ndarray, a: float, c: float, q: float,
                          r: float, x0: float, p0: float) -> float:
    """Return log L of a predictive scalar KF: F = 1 + mu a, Q_d = mu q, R_d = r / mu."""
    x, P, ll = x0, p0, 0.0
    for k in range(len(t) - 1):
        mu = t[k + 1] - t[k]
        S = c * P * c + r / mu
        e = y[k] - c * x
        ll += -0.5 * (np.log(2 * np.pi * S) + e * e / S)
        K = P * c / S
        x, P = x + K * e, P - K * c * P
        F = 1.0 + mu * a
        x, P = F * x, F * P * F + mu * q
    return ll


@pytest.fixture(scope='module')
def sim(tmp_path_factory):
    d = tmp_path_factory.mktemp('fit')
    (d / 'params.yaml').write_text(PARAMS)
    t, y = simulate(d / 'bag', 2000, seed=7)
    rc = fit_noise.main([str(d / 'bag'), '--params-file', str(d / 'params.yaml'),
                         '--out', str(d / 'out' / 'fitted.yaml'),
                         '--json', str(d / 'out' / 'fit.json'), '-q'])
    assert rc == 0
    return d, t, y, json.loads((d / 'out' / 'fit.json').read_text())


def test_recovers_known_q_and_r_within_four_standard_errors(sim):
    # the MLE is asymptotically normal: 4 standard errors is a two-sided 6e-5 tail
    _, _, _, fit = sim
    assert fit['parameters'] == ['Q[0,0]', 'R[0,0]']
    for value, truth, se_log in zip(fit['log_parameters'], (Q_TRUE, R_TRUE),
                                    fit['log_stderr']):
        assert 0.01 < se_log < 0.3
        assert abs(value - np.log(truth)) <= 4 * se_log
    assert fit['Q'][0][0] == pytest.approx(np.exp(fit['log_parameters'][0]), rel=1e-12)
    # delta method: se(q) = q se(log q)
    assert fit['Q_stderr'][0][0] == pytest.approx(fit['Q'][0][0] * fit['log_stderr'][0])
    assert fit['R_stderr'][0][0] == pytest.approx(fit['R'][0][0] * fit['log_stderr'][1])
    assert fit['n'] == 1999 and fit['samples'] == 2000 and fit['gaps'] > 150
    assert fit['optimizer']['success'] and fit['optimizer']['gate_stable']
    assert fit['nis']['consistent']
    assert fit['nis']['band'][0] < 1.0 < fit['nis']['band'][1]


def test_log_likelihood_equals_a_scalar_filter_written_out(sim):
    _, t, y, fit = sim
    q, r = fit['Q'][0][0], fit['R'][0][0]
    ll = scalar_log_likelihood(t, y, A_TRUE, 1.0, q, r, 0.0, 1.0)
    assert fit['log_likelihood'] == pytest.approx(ll, rel=1e-10)
    assert fit['log_likelihood_trace'] == pytest.approx(ll, rel=1e-10)
    # the maximum: a 5% change of q or r lowers the independent likelihood
    for dq, dr in ((1.05, 1), (1 / 1.05, 1), (1, 1.05), (1, 1 / 1.05)):
        assert scalar_log_likelihood(t, y, A_TRUE, 1.0, q * dq, r * dr, 0.0, 1.0) < ll
    ll0 = scalar_log_likelihood(t, y, A_TRUE, 1.0, 1.0, 1.0, 0.0, 1.0)
    assert fit['params_file']['log_likelihood'] == pytest.approx(ll0, rel=1e-10)


def test_the_fitted_file_runs_the_node_session(sim):
    d, t, y, fit = sim
    config = load_config(d / 'out' / 'fitted.yaml').session
    assert config.model.Q[0, 0] == pytest.approx(fit['Q'][0][0], rel=1e-12)
    assert config.model.R[0, 0] == pytest.approx(fit['R'][0][0], rel=1e-12)
    assert config.model.A[0, 0] == A_TRUE and config.gate == 10.0
    session = EstimatorSession(config)
    statuses = {session.add(int(round(tk * 1e9)), yk).status for tk, yk in zip(t, y)}
    assert statuses == {'accepted'}
    assert not list((d / 'out').glob('*.part'))


def test_session_innovations_equal_the_core_trace(sim, tmp_path):
    # the session path (outcomes) against the core re-run of its trace, with a late sample,
    # and on the drogue bag (inputs, measurements merged into input points, exact transition)
    d, t, y, _ = sim
    config = load_config(d / 'params.yaml').session
    events = [Measurement(int(round(tk * 1e9)), yk) for tk, yk in zip(t[:300], y[:300])]
    events[100], events[101] = events[101], events[100]
    drogue = load_config(REPO / 'config' / 'drogue_estimator.yaml').session
    drogue_events = read_stream(REPO / 'bags' / 'drogue', drogue).events
    for cfg, evs in ((config, events), (drogue, drogue_events)):
        run = run_stream(cfg, evs)
        assert run.stats.inserted == (1 if cfg is config else 0)
        trace = run_trace(cfg.model, cfg.transition, run.segments)
        assert run.innovations.count == trace.count > 10
        np.testing.assert_allclose(run.innovations.e, trace.e, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(run.innovations.S, trace.S, rtol=1e-12)


def test_errors_are_one_line_and_write_nothing(sim, tmp_path, capsys, monkeypatch):
    d = sim[0]
    out, js = tmp_path / 'f.yaml', tmp_path / 'f.json'
    few = tmp_path / 'few'
    simulate(few, 8, seed=1)
    cases = [([str(d / 'bag'), '--topic', '/nothing'], 1, 'no topic /nothing'),
             ([str(few)], 1, 'too few samples'),
             ([str(tmp_path / 'absent')], 1, 'no such bag')]
    for argv, code, text in cases:
        rc = fit_noise.main(argv + ['--params-file', str(d / 'params.yaml'), '--out', str(out),
                                    '--json', str(js)])
        err = capsys.readouterr().err
        assert rc == code and text in err and len(err.strip().splitlines()) == 1, err
        assert not out.exists() and not js.exists()

    def no_convergence(*args, **kwargs):
        raise noise_fit.FitError('the optimiser did not converge (test)')
    monkeypatch.setattr('tskf_ros.owc.innovation_trace.fit', no_convergence)
    rc = fit_noise.main([str(d / 'bag'), '--params-file', str(d / 'params.yaml'),
                         '--out', str(out), '--json', str(js)])
    err = capsys.readouterr().err
    assert rc == fit_noise.EXIT_NO_FIT and 'did not converge' in err
    assert not out.exists() and not js.exists()


@pytest.mark.slow
def test_standard_errors_match_the_spread_over_seeds(tmp_path):
    # Monte Carlo: the Hessian standard error against the spread of the estimates
    (tmp_path / 'params.yaml').write_text(PARAMS)
    est, se = [], []
    for seed in range(6):
        simulate(tmp_path / f'b{seed}', 2000, seed=100 + seed)
        assert fit_noise.main([str(tmp_path / f'b{seed}'), '--params-file',
                               str(tmp_path / 'params.yaml'), '--json',
                               str(tmp_path / f'f{seed}.json'), '-q']) == 0
        fit = json.loads((tmp_path / f'f{seed}.json').read_text())
        est.append(fit['log_parameters'])
        se.append(fit['log_stderr'])
    spread = np.std(est, axis=0, ddof=1)
    ratio = spread / np.mean(se, axis=0)
    print(f'log q, log r: mean estimate {np.mean(est, axis=0)} (truth '
          f'{np.log([Q_TRUE, R_TRUE])}), spread over seeds {spread}, mean Hessian '
          f'standard error {np.mean(se, axis=0)}, ratio {ratio}')
    # with 6 seeds the sample sd is within a factor of about 2 of the truth (chi2(5))
    assert np.all((ratio > 0.35) & (ratio < 2.0)), ratio
    assert np.all(np.abs(np.mean(est, axis=0) - np.log([Q_TRUE, R_TRUE]))
                  < 3 * np.mean(se, axis=0) / np.sqrt(6) + 0.05)


def test_a_message_that_does_not_deserialize_is_damage(tmp_path, capsys):
    # 300 good samples, then bytes that are not an Illuminance: fitted on what came before
    bag = tmp_path / 'bad'
    t, y = simulate(tmp_path / 'good', 300, seed=2)
    write_samples(bag, t, y, tail=b'\x00\x01\x00\x00garbage')
    out = tmp_path / 'f.json'
    # Q at its true value, fixed: R is determined by 300 samples
    (tmp_path / 'q.yaml').write_text(PARAMS.replace('Q: [1.0]', f'Q: [{Q_TRUE}]'))
    rc = fit_noise.main([str(bag), '--params-file', str(tmp_path / 'q.yaml'), '--json',
                         str(out), '--fix', 'Q', '-q'])
    err = capsys.readouterr().err
    assert rc == 3 and 'does not deserialize' in err and len(err.strip().splitlines()) == 1
    fit = json.loads(out.read_text())
    assert fit['samples'] == 300 and 'does not deserialize' in fit['damage']


def test_absurd_readings_are_left_to_the_gate(tmp_path):
    # 1e300 is finite: with the gate off it would make the likelihood infinite; the node's
    # gate rejects it, and so the fit leaves it out and still recovers Q and R
    (tmp_path / 'params.yaml').write_text(PARAMS)
    simulate(tmp_path / 'bag', 2000, seed=7, spikes=(500, 1500))
    assert fit_noise.main([str(tmp_path / 'bag'), '--params-file',
                           str(tmp_path / 'params.yaml'), '--json', str(tmp_path / 'f.json'),
                           '-q']) == 0
    fit = json.loads((tmp_path / 'f.json').read_text())
    assert fit['excluded_by_gate'] == 2 and fit['rejected'] == {'gated': 2}
    assert fit['n'] == 1997 and fit['optimizer']['gate_stable']
    for value, truth, se_log in zip(fit['log_parameters'], (Q_TRUE, R_TRUE),
                                    fit['log_stderr']):
        assert abs(value - np.log(truth)) <= 4 * se_log


def test_a_params_file_reads_as_the_node_reads_it(sim, tmp_path, capsys):
    # rcl's parser reads 1e-2 and 1.0e-2 as doubles (PyYAML's YAML 1.1 would make them
    # strings); a file that is not a mapping is one line, exit 1
    d = sim[0]
    text = PARAMS.replace('Q: [1.0]', 'Q: [1.0e-2]').replace('R: [1.0]', 'R: [1e0]')
    (tmp_path / 'e.yaml').write_text(text)
    out = tmp_path / 'f.yaml'
    assert load_config(tmp_path / 'e.yaml').session.model.Q[0, 0] == 0.01
    assert fit_noise.main([str(d / 'bag'), '--params-file', str(tmp_path / 'e.yaml'),
                           '--out', str(out), '-q']) == 0
    fitted = load_config(out).session.model
    assert 0.0 < fitted.Q[0, 0] < 1.0 and 0.0 < fitted.R[0, 0] < 1.0
    for bad in ('- 1\n- 2\n', '/**:\n  ros__parameters: 5\n'):
        (tmp_path / 'bad.yaml').write_text(bad)
        rc = fit_noise.main([str(d / 'bag'), '--params-file', str(tmp_path / 'bad.yaml')])
        err = capsys.readouterr().err
        assert rc == 1 and 'bad.yaml' in err and len(err.strip().splitlines()) == 1, err


def test_ctrl_c_is_one_line_and_writes_nothing(sim, tmp_path, capsys, monkeypatch):
    d = sim[0]

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(fit_noise, 'fit_events', interrupted)
    out, js = tmp_path / 'f.yaml', tmp_path / 'f.json'
    rc = fit_noise.main([str(d / 'bag'), '--params-file', str(d / 'params.yaml'),
                         '--out', str(out), '--json', str(js)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 130 and len(err) == 1 and 'interrupted' in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_no_output_may_be_a_file_of_the_input_bag(sim, tmp_path, capsys):
    # --json BAG/BAG.mcap would replace the recording with JSON
    d = sim[0]
    bag = tmp_path / 'bag'
    simulate(bag, 40, seed=3)
    before = {p.name: p.read_bytes() for p in bag.iterdir()}
    mcap = next(bag.glob('*.mcap'))
    (tmp_path / 'link.json').symlink_to(mcap)
    for option, target in (('--json', mcap), ('--out', bag / 'metadata.yaml'),
                           ('--json', bag), ('--json', bag / 'new.json'),
                           ('--out', tmp_path / 'link.json'), ('--json', tmp_path)):
        rc = fit_noise.main([str(bag), '--params-file', str(d / 'params.yaml'), option,
                             str(target), '--fix', 'R'])
        assert rc == 1, target
        one_line(capsys.readouterr().err, '', 'input bag')
        assert {p.name: p.read_bytes() for p in bag.iterdir()} == before
    # the bag given as its .mcap file: its directory is protected all the same
    rc = fit_noise.main([str(mcap), '--params-file', str(d / 'params.yaml'), '--json',
                         str(bag / 'fit.json'), '--fix', 'R'])
    assert rc == 1 and not (bag / 'fit.json').exists()
    one_line(capsys.readouterr().err, '', 'input bag')
    with pytest.raises(SystemExit) as exit_:
        fit_noise.main([str(bag), '--out', str(tmp_path / 'a'), '--json', str(tmp_path / 'a')])
    assert exit_.value.code == 2 and 'same file' in capsys.readouterr().err


def test_ctrl_c_while_reading_is_an_interrupt_not_damage(sim, tmp_path, capsys, monkeypatch):
    # rclpy's deserialize_message turns a KeyboardInterrupt raised inside it into its own
    # error; the partial bag must not be fitted and written as a damaged one
    import signal
    from tskf_ros.experiments import bag_analysis
    d = sim[0]
    real, calls = bag_analysis.deserialize_message, []

    def interrupted_inside(data, cls):
        calls.append(1)
        if len(calls) == 50:
            try:
                signal.raise_signal(signal.SIGINT)
            except KeyboardInterrupt:
                pass                # swallowed by the extension...
            raise RuntimeError('Failed to deserialize ROS message')    # ...which says this
        return real(data, cls)

    monkeypatch.setattr(bag_analysis, 'deserialize_message', interrupted_inside)
    out = tmp_path / 'o'
    handler = signal.getsignal(signal.SIGINT)
    rc = fit_noise.main([str(d / 'bag'), '--params-file', str(d / 'params.yaml'),
                         '--out', str(out / 'f.yaml'), '--json', str(out / 'f.json')])
    assert rc == 130
    one_line(capsys.readouterr().err, '', 'interrupted', 'nothing written')
    assert not out.exists()
    assert signal.getsignal(signal.SIGINT) is handler


@pytest.mark.parametrize('swallowed', ['swallowed', 'system_error'])
def test_ctrl_c_in_the_compiled_kernels_ends_the_fit_at_once(sim, tmp_path, capsys,
                                                             monkeypatch, swallowed):
    # numba's dispatcher (C) may drop the KeyboardInterrupt of a Ctrl-C that lands in
    # the Python it calls, or return it as a SystemError: the fit ends at the next
    # evaluation, with the one line, not minutes later or with a traceback
    import signal
    from tskf_ros.core import noise_fit
    d = sim[0]
    real, calls = noise_fit.negative_log_likelihood, []

    def interrupted_inside(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            try:
                signal.raise_signal(signal.SIGINT)
            except KeyboardInterrupt:
                if swallowed == 'system_error':
                    raise SystemError('CPUDispatcher(<function update_predict>) returned '
                                      'a result with an exception set') from None
        return real(*args, **kwargs)

    monkeypatch.setattr(noise_fit, 'negative_log_likelihood', interrupted_inside)
    out = tmp_path / 'o'
    rc = fit_noise.main([str(d / 'bag'), '--params-file', str(d / 'params.yaml'),
                         '--out', str(out / 'f.yaml'), '--json', str(out / 'f.json')])
    assert rc == 130 and len(calls) == 3
    one_line(capsys.readouterr().err, '', 'interrupted', 'nothing written')
    assert not out.exists()


def test_ctrl_c_while_writing_writes_nothing(sim, tmp_path, capsys, monkeypatch):
    d = sim[0]
    import tskf_ros.experiments.output as output
    real = output.os.replace
    done = []

    def interrupted_replace(src, dst):
        if done:
            raise KeyboardInterrupt
        done.append(dst)
        return real(src, dst)
    monkeypatch.setattr(output.os, 'replace', interrupted_replace)
    rc = fit_noise.main([str(d / 'bag'), '--params-file', str(d / 'params.yaml'), '--fix', 'R',
                         '--out', str(tmp_path / 'f.yaml'), '--json', str(tmp_path / 'f.json')])
    assert rc == 130
    one_line(capsys.readouterr().err, '', 'interrupted')
    # the first file was renamed into place before the interrupt: removed again
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_bad_out_writes_no_json(sim, tmp_path, capsys):
    d = sim[0]
    (tmp_path / 'file').write_text('')
    js = tmp_path / 'f.json'
    for bad in (tmp_path / 'file' / 'f.yaml', tmp_path):     # under a file; a directory
        rc = fit_noise.main([str(d / 'bag'), '--params-file', str(d / 'params.yaml'),
                             '--fix', 'R', '--json', str(js), '--out', str(bad)])
        assert rc == 1
        one_line(capsys.readouterr().err)
        assert not js.exists() and not list(tmp_path.glob('.*part'))


def test_a_start_far_from_the_truth_is_found(sim, tmp_path):
    # e^30 from the truth: beyond the first search window of e^+-25 around the start
    d, *_, truth_fit = sim
    far = PARAMS.replace('Q: [1.0]', f'Q: [{float(Q_TRUE * np.exp(30.0))!r}]').replace(
        'R: [1.0]', f'R: [{float(R_TRUE * np.exp(-30.0))!r}]')
    (tmp_path / 'far.yaml').write_text(far)
    assert fit_noise.main([str(d / 'bag'), '--params-file', str(tmp_path / 'far.yaml'),
                           '--json', str(tmp_path / 'f.json'), '-q']) == 0
    fit = json.loads((tmp_path / 'f.json').read_text())
    assert fit['undetermined'] == [] and fit['optimizer']['at_bound'] == []
    np.testing.assert_allclose(fit['log_parameters'], truth_fit['log_parameters'], atol=1e-3)


def test_an_undetermined_parameter_keeps_the_configured_value(tmp_path, capsys):
    # at 1 Hz with model (3), R is flat towards 0: not written, said, marked in the JSON
    params = REPO / 'config' / 'owc_estimator.yaml'
    configured = load_config(params).session.model
    rc = fit_noise.main([str(REPO / 'bags' / 'owc_cai_td_1hz'), '--params-file', str(params),
                         '--out', str(tmp_path / 'f.yaml'), '--json', str(tmp_path / 'f.json')])
    out = capsys.readouterr().out
    assert rc == 0
    fit = json.loads((tmp_path / 'f.json').read_text())
    assert fit['undetermined'] == ['R[0,0]']
    assert fit['written']['R'] == [[configured.R[0, 0]]]
    assert fit['written']['Q'] == fit['Q'] and fit['Q'][0][0] != configured.Q[0, 0]
    written = load_config(tmp_path / 'f.yaml').session.model
    assert written.R[0, 0] == configured.R[0, 0]
    assert written.Q[0, 0] == pytest.approx(fit['Q'][0][0], rel=1e-12)
    assert 'R[0,0] is not determined' in out and 'is kept' in out
    assert 'not written' in out


def test_the_node_ranges_refuse_a_params_file(sim, tmp_path, capsys):
    d = sim[0]
    for line, name in (('period: 1.0e-300', 'period'), ('jump_factor: 0.0', 'jump_factor'),
                       ('dense_fraction: 7.0', 'dense_fraction'),
                       ('max_jump: 1.0e+308', 'max_jump')):
        (tmp_path / 'p.yaml').write_text(PARAMS + f'    {line}\n')
        rc = fit_noise.main([str(d / 'bag'), '--params-file', str(tmp_path / 'p.yaml'),
                             '--json', str(tmp_path / 'f.json')])
        assert rc == 1
        one_line(capsys.readouterr().err, '', name, 'range')
        assert not (tmp_path / 'f.json').exists()


def test_a_bag_of_another_model_is_refused(capsys):
    # the drogue bag has inputs and truth of displacement and velocity: not model (3)
    rc = fit_noise.main([str(REPO / 'bags' / 'drogue'), '--params-file',
                         str(REPO / 'config' / 'owc_estimator.yaml')])
    assert rc == 1
    one_line(capsys.readouterr().err, '', 'another model', '/input')
    rc = fit_noise.main([str(REPO / 'bags' / 'led_alignment'), '--params-file',
                         str(REPO / 'config' / 'owc_estimator.yaml')])
    assert rc == 1
    one_line(capsys.readouterr().err, '', 'another model', '/alignment/truth')


def test_the_likelihood_is_shown_as_it_improves(sim, monkeypatch, capsys):
    d, *_ = sim
    seen = []
    config = load_config(d / 'params.yaml').session
    events = read_stream(d / 'bag', config).events
    sf, report = fit_noise.fit_events(config, events, fit_R=False,
                                      progress=lambda k, ll: seen.append((k, ll)))
    assert [k for k, _ in seen] == list(range(1, len(seen) + 1))
    lls = [ll for _, ll in seen]
    assert all(b >= a for a, b in zip(lls, lls[1:]))
    # the last evaluations are the Hessian's, around the maximum
    assert lls[-1] == pytest.approx(sf.result.log_likelihood, rel=1e-9)

    class Terminal:
        """stderr as a terminal (tqdm draws only there)."""

        def __init__(self):
            self.text = []

        def isatty(self):
            return True

        def write(self, s):
            self.text.append(s)

        def flush(self):
            pass
    term = Terminal()
    monkeypatch.setattr('sys.stderr', term)
    assert fit_noise.main([str(d / 'bag'), '--params-file', str(d / 'params.yaml'),
                           '--fix', 'R']) == 0
    shown = ''.join(term.text)
    assert 'reading' in shown and 'fitting' in shown and 'log L -' in shown
    term.text.clear()
    assert fit_noise.main([str(d / 'bag'), '--params-file', str(d / 'params.yaml'),
                           '--fix', 'R', '-q']) == 0
    assert ''.join(term.text) == ''


@pytest.mark.parametrize('stop, code, text', [
    (KeyboardInterrupt, 130, 'interrupted'),
    (lambda: OSError(28, 'No space left on device'), 1, 'No space left on device')])
def test_the_temporary_files_are_freed_on_ctrl_c_and_on_an_error(
        sim, tmp_path, capsys, monkeypatch, stop, code, text):
    # the events, the filter steps and the innovations are in temporary files while the
    # likelihood is maximised; a Ctrl-C or an error (a full disk) in the middle of it
    # leaves none open, and none ever had a name in the folder
    d = sim[0]
    spill = tmp_path / 'spill'
    spill.mkdir()
    monkeypatch.setattr(tempfile, 'tempdir', str(spill))
    monkeypatch.setattr(spill_rows, 'BLOCK', 64)       # files made for 2000 samples
    seen = []
    likelihood = noise_fit.trace_log_likelihood

    def stopped(*args, **kwargs):
        seen.append(len(open_files_in(spill)))
        if len(seen) == 3:
            raise stop()
        return likelihood(*args, **kwargs)
    monkeypatch.setattr(noise_fit, 'trace_log_likelihood', stopped)
    js = tmp_path / 'f.json'
    rc = fit_noise.main([str(d / 'bag'), '--params-file', str(d / 'params.yaml'),
                         '--json', str(js)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == code and len(err) == 1 and text in err[0], err
    assert seen[-1] >= 3                    # events, steps, innovations were open then
    gc.collect()
    assert open_files_in(spill) == [] and list(spill.iterdir()) == [] and not js.exists()
