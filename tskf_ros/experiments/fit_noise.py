"""
fit_noise: maximum-likelihood Q and R of the estimator's model from a bag.

    (Q, R) = argmin over log diag(Q), log diag(R) of  sum_k [log det S_k + e_k^T S_k^-1 e_k]

over the time-scale filter's innovations e_k and their covariances S_k (mu from the stamps).
"""

import argparse
import copy
from dataclasses import replace
from pathlib import Path
import sys
from typing import Optional

import numpy as np
import scipy.stats

from tskf_ros.bag.bag_errors import EXIT_INTERRUPTED
from tskf_ros.bag.message_types import BagTypeError
from tskf_ros.bag.reader import BagError, error_exit, exit_status
from tskf_ros.core.noise_fit import FitError, negative_log_likelihood, nis_summary
from tskf_ros.experiments.bag_analysis import read_stream
from tskf_ros.experiments.output import write_json, write_text
from tskf_ros.messages.estimator_interface import load_config, NODE_NAME, ParamsError
from tskf_ros.messages.parameters import read_params_yaml
from tskf_ros.owc.innovation_trace import fit_stream, Measurement, run_stream, StreamFit
from tskf_ros.owc.session import EstimatorConfig

import yaml

PROG = 'fit_noise'
EXIT_NO_FIT = 4
# a standard error of a log-parameter above this (a factor e) leaves it undetermined
POORLY_DETERMINED = 1.0


class NoFitError(FitError):
    """A fit whose maximum cannot be used (at a bound, or a singular Hessian)."""


def fit_events(config: EstimatorConfig, events: list, *, fit_Q: bool = True,
               fit_R: bool = True) -> tuple[StreamFit, dict]:
    """Fit Q and R to a stream; return the fit and its JSON-ready report."""
    sf = fit_stream(config, events, fit_Q=fit_Q, fit_R=fit_R)
    res, run = sf.result, sf.run
    p = config.model.C.shape[0]
    # the parameter file's own Q and R on the same steps, for a likelihood-ratio test
    base = replace(config, gate=0.0, use_message_variance=False)
    trace = run_stream(base, [ev for ev in events if not isinstance(ev, Measurement)
                              or int(ev.stamp_ns) not in sf.excluded])
    ll0 = -negative_log_likelihood(config.model, config.transition, trace.segments)
    lr = 2.0 * (res.log_likelihood - ll0)
    k = len(res.names)
    st = run.stats
    for name, se in zip(res.names, res.theta_stderr):
        if se > POORLY_DETERMINED:
            sf.notes.append(f'{name} is not determined by this bag: the standard error of its '
                            f'log is {se:.3g} (a factor e^{se:.3g}); consider --fix')
    report = {
        'Q': res.Q, 'R': res.R, 'Q_stderr': res.Q_stderr, 'R_stderr': res.R_stderr,
        'log_likelihood': run.innovations.log_likelihood(),
        'log_likelihood_trace': res.log_likelihood,
        'parameters': res.names, 'log_parameters': res.theta,
        'log_stderr': res.theta_stderr, 'covariance_log_parameters': res.covariance_log,
        'nis': nis_summary(run.innovations.nis, p),
        'n': run.innovations.count, 'samples': run.measurements, 'inputs': run.inputs,
        'gaps': st.gaps_total, 'gap_max_s': max(st.gaps.values()) if st.gaps else 0.0,
        'resets': {r: n for r, n in st.resets.items() if n},
        'rejected': {r: n for r, n in st.rejected.items() if n},
        'excluded_by_gate': len(sf.excluded),
        'transition': config.transition, 'period': config.period,
        'params_file': {'Q': config.model.Q, 'R': config.model.R, 'log_likelihood': ll0,
                        'likelihood_ratio': lr,
                        'p_value': float(scipy.stats.chi2.sf(max(lr, 0.0), k))},
        'optimizer': {'success': res.success, 'message': res.message,
                      'evaluations': res.evaluations, 'at_bound': res.at_bound,
                      'hessian_positive_definite': res.hessian_ok, 'gate_rounds': sf.rounds,
                      'gate_stable': sf.gate_stable},
        'notes': sf.notes,
    }
    return sf, report


def fitted_parameters(params_file: Optional[Path], Q: np.ndarray, R: np.ndarray,
                      use_message_variance_off: bool) -> str:
    """Return the parameter file's text with Q and R replaced (the node's section)."""
    doc: dict = {}
    if params_file:
        doc = copy.deepcopy(read_params_yaml(Path(params_file).read_text()) or {})
    key = next((k for k in (NODE_NAME, '/' + NODE_NAME, '/**/' + NODE_NAME, '/**')
                if isinstance(doc.get(k), dict) and 'ros__parameters' in doc[k]),
               '/**/' + NODE_NAME)
    section = doc.setdefault(key, {}).setdefault('ros__parameters', {})
    section['Q'] = [float(v) for v in np.ravel(Q)]
    section['R'] = [float(v) for v in np.ravel(R)]
    if use_message_variance_off:
        section['use_message_variance'] = False
    head = (f'# {PROG}: Q and R fitted by maximum likelihood over the innovations of '
            f'{params_file or "the default parameters"}\n')
    return head + yaml.safe_dump(doc, default_flow_style=None, sort_keys=False)


def check_usable(sf: StreamFit) -> None:
    """Raise NoFitError if a parameter ran to its bound or the Hessian is singular."""
    res = sf.result
    if res.at_bound:
        raise NoFitError(f'{", ".join(res.at_bound)} ran to the search bound (e^+-25 times '
                         'the start): the data do not determine it; fix it with --fix')
    if not res.hessian_ok:
        raise NoFitError('the Hessian of the likelihood is not positive definite at the '
                         'optimum: Q and R are not both identifiable from this bag (try --fix)')


def main(argv: Optional[list] = None) -> int:
    """Run the command line; return the exit status."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Fit the noise intensities Q and R of the estimator model to a '
        "bag by maximum likelihood over the time-scale filter's innovations.")
    parser.add_argument('bag', type=Path, help='bag directory or .mcap file')
    parser.add_argument('--params-file', type=Path,
                        help='estimator parameters (the model and the start of the search), '
                        "e.g. config/owc_estimator.yaml; default: the node's defaults")
    parser.add_argument('--topic', help='measurement topic (default /received_power, else the '
                        'only stamped scalar topic)')
    parser.add_argument('--input-topic', help='input u topic (default /input if present)')
    parser.add_argument('--out', type=Path, help='write the fitted parameter file here')
    parser.add_argument('--json', type=Path, help='write the fit report (JSON) here')
    parser.add_argument('--fix', choices=('Q', 'R'), action='append', default=[],
                        help="keep Q (or R) at the parameter file's value; fit the other")
    parser.add_argument('-q', '--quiet', action='store_true', help='only errors')
    args = parser.parse_args(argv)
    if args.out and args.params_file and args.out.resolve() == args.params_file.resolve():
        parser.error('--out is the parameter file: write the fit to another file')
    try:
        config = load_config(args.params_file).session
        stream = read_stream(args.bag, config, topic=args.topic, input_topic=args.input_topic,
                             truth=False)
        if stream.measurements == 0:
            raise FitError(f'{args.bag}: no messages on {stream.topic}'
                           + (f' ({stream.damage})' if stream.damage is not None else ''))
        sf, report = fit_events(config, stream.events, fit_Q='Q' not in args.fix,
                                fit_R='R' not in args.fix)
    except (BagError, BagTypeError, ParamsError, OSError) as exc:
        return error_exit(PROG, exc, args.bag)
    except FitError as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return EXIT_NO_FIT if 'converge' in str(exc) else 1
    except ValueError as exc:       # a config the fitted Q, R make unusable (ConfigError)
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return EXIT_NO_FIT
    except KeyboardInterrupt:
        print(f'{PROG}: interrupted; nothing written', file=sys.stderr)
        return EXIT_INTERRUPTED
    try:
        check_usable(sf)
    except NoFitError as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return EXIT_NO_FIT
    report['bag'] = str(args.bag)
    report['topic'] = stream.topic
    report['damage'] = str(stream.damage) if stream.damage is not None else None
    try:
        if args.json:
            write_json(args.json, report)
        if args.out:
            write_text(args.out, fitted_parameters(args.params_file, sf.result.Q, sf.result.R,
                                                   bool(sf.notes and config.use_message_variance)))
    except OSError as exc:
        return error_exit(PROG, exc, args.out)
    if not args.quiet:
        res, nis = sf.result, report['nis']
        for name, t, se in zip(res.names, res.theta, res.theta_stderr):
            print(f'{name} = {np.exp(t):.6g} (stderr {np.exp(t) * se:.3g}; log {t:.4f} +- '
                  f'{se:.4f})')
        print(f'log-likelihood {report["log_likelihood"]:.3f} over {report["n"]} steps '
              f'(the parameter file\'s Q, R: {report["params_file"]["log_likelihood"]:.3f}); '
              f'NIS mean {nis["mean"]:.4f}, 95% band [{nis["band"][0]:.4f}, '
              f'{nis["band"][1]:.4f}] ({"consistent" if nis["consistent"] else "outside"}); '
              f'{report["gaps"]} gaps, {report["excluded_by_gate"]} gated')
        for note in sf.notes:
            print(f'{PROG}: note: {note}')
    return exit_status(PROG, stream.damage, 'input damaged; fitted on the messages before it')


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    console_main()
