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
fit_noise: maximum-likelihood Q and R of the estimator's model from a bag.

    (Q, R) = argmin over log diag(Q), log diag(R) of  sum_k [log det S_k + e_k^T S_k^-1 e_k]

over the time-scale filter's innovations e_k and their covariances S_k (mu from the stamps).
"""

import argparse
import copy
from dataclasses import replace
from pathlib import Path
import sys
from typing import Iterable, Optional

import numpy as np
import scipy.stats

from tskf_ros.bag import progress
from tskf_ros.bag.bag_errors import EXIT_INTERRUPTED
from tskf_ros.bag.message_types import BagTypeError
from tskf_ros.bag.outputs import check_outputs
from tskf_ros.bag.progress import Interrupts
from tskf_ros.bag.reader import BagError, error_exit, exit_status
from tskf_ros.core.noise_fit import FitError, FitResult, negative_log_likelihood
from tskf_ros.core.noise_search import FitProgress, LOG_SEARCH_RADIUS, RECENTRES
from tskf_ros.experiments.bag_analysis import read_stream
from tskf_ros.experiments.output import json_bytes, write_all
from tskf_ros.messages.estimator_interface import load_config, NODE_NAME, ParamsError
from tskf_ros.messages.parameters import read_params_yaml
from tskf_ros.owc.innovation_trace import Event, fit_stream, run_stream, StreamFit, without
from tskf_ros.owc.session import EstimatorConfig

import yaml

PROG = 'fit_noise'
EXIT_NO_FIT = 4
# a standard error of a log-parameter above this (a factor e) leaves it undetermined
POORLY_DETERMINED = 1.0


class NoFitError(FitError):
    """A fit whose maximum cannot be used (at a bound, or a singular Hessian)."""


def entry(name: str) -> tuple[str, int]:
    """Return the matrix ('Q' or 'R') and diagonal index i of a parameter name 'Q[i,i]'."""
    return name[0], int(name[2:].split(',')[0])


def undetermined(res: FitResult) -> list[str]:
    """Return the parameters the data do not determine: at a bound, or a large stderr."""
    return [name for name, se in zip(res.names, res.theta_stderr)
            if name in res.at_bound or not se <= POORLY_DETERMINED]


def kept_values(config: EstimatorConfig, res: FitResult) -> tuple[np.ndarray, np.ndarray]:
    """Return (Q, R) to write: the fit, with each undetermined entry the configured one."""
    Q, R = np.array(res.Q, dtype=float), np.array(res.R, dtype=float)
    for name in undetermined(res):
        which, i = entry(name)
        target, source = (Q, config.model.Q) if which == 'Q' else (R, config.model.R)
        target[i, i] = source[i, i]
    return Q, R


def fit_events(config: EstimatorConfig, events: Iterable[Event], *, fit_Q: bool = True,
               fit_R: bool = True, progress: Optional[FitProgress] = None
               ) -> tuple[StreamFit, dict]:
    """
    Fit Q and R to a stream; return the fit and its JSON-ready report.

    events: an EventColumns (read_stream's) or a list, iterated once per session run.
    """
    sf = fit_stream(config, events, fit_Q=fit_Q, fit_R=fit_R, progress=progress)
    res, run = sf.result, sf.run
    # the parameter file's own Q and R on the same steps, for a likelihood-ratio test
    # (the fit's last round's steps, unless the gated set changed after it)
    ll0 = sf.file_log_likelihood
    if not sf.gate_stable:
        base = replace(config, gate=0.0, use_message_variance=False)
        trace = run_stream(base, without(events, sf.excluded))
        ll0 = -negative_log_likelihood(config.model, config.transition, trace.segments)
    lr = 2.0 * (res.log_likelihood - ll0)
    k = len(res.names)
    st = run.stats
    for name, t, se in zip(res.names, res.theta, res.theta_stderr):
        which, i = entry(name)
        kept = (config.model.Q if which == 'Q' else config.model.R)[i, i]
        keep = f"the parameter file's value {kept:.6g} is kept (fix it with --fix {which})"
        if name in res.at_bound:
            sf.notes.append(f'{name} is not determined by this bag: the likelihood still rises '
                            f'towards {"0" if t < 0 else "infinity"} at {np.exp(t):.3g}, '
                            f'e^{abs(t - (np.log(kept) if kept > 0 else 0.0)):.0f} from '
                            f'the start, with no maximum; {keep}')
        elif not se <= POORLY_DETERMINED:
            sf.notes.append(f'{name} is not determined by this bag: the standard error of its '
                            f'log is {se:.3g} (a factor e^{se:.3g}); {keep}')
    Q_out, R_out = kept_values(config, res)
    report = {
        'Q': res.Q, 'R': res.R, 'Q_stderr': res.Q_stderr, 'R_stderr': res.R_stderr,
        'log_likelihood': run.innovations.log_likelihood(),
        'log_likelihood_trace': res.log_likelihood,
        'parameters': res.names, 'log_parameters': res.theta,
        'log_stderr': res.theta_stderr, 'covariance_log_parameters': res.covariance_log,
        'nis': run.innovations.nis_summary(),
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
        'undetermined': undetermined(res),
        'written': {'Q': Q_out, 'R': R_out},
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
    """Raise NoFitError if the data determine none of the parameters fitted."""
    res = sf.result
    if len(undetermined(res)) < len(res.names):
        return
    if res.at_bound and len(res.at_bound) == len(res.names):
        raise NoFitError(f'{", ".join(res.at_bound)}: the likelihood keeps rising towards a '
                         f'bound (searched e^{LOG_SEARCH_RADIUS * (RECENTRES + 1):.0f} '
                         'around the start) with no maximum: the data do not determine '
                         'them; fix one with --fix')
    if not res.hessian_ok:
        raise NoFitError('the Hessian of the likelihood is not positive definite at the '
                         'optimum: Q and R are not both identifiable from this bag (try --fix)')
    spread = ', '.join(f'{n}: {se:.3g}' for n, se in zip(res.names, res.theta_stderr))
    raise NoFitError(f'this bag determines none of {", ".join(res.names)} (the standard '
                     f'errors of their logs, {spread}, exceed {POORLY_DETERMINED:g}): nothing '
                     'fitted; try --fix')


def main(argv: Optional[list] = None) -> int:
    """Run the command line; return the exit status."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Fit the noise intensities Q and R of the estimator model to a '
        "bag by maximum likelihood over the time-scale filter's innovations.",
        epilog='exit status: 0 fitted; 1 the bag, the parameters or an output could not be '
        'used; 3 the input was damaged (fitted on what came before); 4 no usable fit; 130 '
        'interrupted.  Nothing is written unless every output can be written.')
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
    parser.add_argument('-q', '--quiet', action='store_true',
                        help='only errors (no progress bars, no results)')
    args = parser.parse_args(argv)
    outputs = [p for p in (args.out, args.json) if p is not None]
    if args.out and args.json and args.out.resolve() == args.json.resolve():
        parser.error('--out and --json are the same file')
    if args.params_file and any(p.resolve() == args.params_file.resolve() for p in outputs):
        parser.error('an output is the parameter file: write the fit to another file')
    with Interrupts() as interrupts:
        try:
            return _run(args, outputs, interrupts)
        except Exception:  # noqa: B902 - after a Ctrl-C, what a library made of it
            if not interrupts.seen:     # (numba's dispatcher: a SystemError)
                raise
            print(f'{PROG}: interrupted; nothing written', file=sys.stderr)
            return EXIT_INTERRUPTED
        except KeyboardInterrupt:
            print(f'{PROG}: interrupted; nothing written', file=sys.stderr)
            return EXIT_INTERRUPTED


def _run(args: argparse.Namespace, outputs: list, interrupts: Interrupts) -> int:
    """Read, fit and write (all or nothing); Ctrl-C in any phase raises KeyboardInterrupt."""
    show = not args.quiet
    try:
        check_outputs(outputs, [args.bag])
        config = load_config(args.params_file).session
        stream = read_stream(args.bag, config, topic=args.topic, input_topic=args.input_topic,
                             truth=False, progress=show)
        interrupts.check()
        if stream.measurements == 0:
            raise FitError(f'{args.bag}: no messages on {stream.topic}'
                           + (f' ({stream.damage})' if stream.damage is not None else ''))
        bar = progress.bar(None, 'fitting Q, R', 'eval', show)

        def improved(evaluations: int, log_likelihood: float) -> None:
            # after each evaluation: a Ctrl-C that C code swallowed (numba's dispatcher,
            # numpy) ends the fit here instead of after it
            interrupts.check()
            bar.update(1)
            bar.set_postfix_str(f'log L {log_likelihood:.4f}', refresh=False)
        try:
            sf, report = fit_events(config, stream.events, fit_Q='Q' not in args.fix,
                                    fit_R='R' not in args.fix, progress=improved)
        finally:
            bar.close()
        interrupts.check()
        check_usable(sf)
    except (BagError, BagTypeError, ParamsError, OSError) as exc:
        interrupts.check()
        return error_exit(PROG, exc, args.bag)
    except FitError as exc:         # NoFitError too
        interrupts.check()
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return EXIT_NO_FIT if 'converge' in str(exc) or isinstance(exc, NoFitError) else 1
    except ValueError as exc:       # a config the fitted Q, R make unusable (ConfigError)
        interrupts.check()
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return EXIT_NO_FIT
    report['bag'] = str(args.bag)
    report['topic'] = stream.topic
    report['damage'] = str(stream.damage) if stream.damage is not None else None
    files = []
    if args.json:
        files.append((args.json, json_bytes(report)))
    if args.out:
        Q, R = report['written']['Q'], report['written']['R']
        files.append((args.out, fitted_parameters(
            args.params_file, Q, R, bool(sf.notes and config.use_message_variance)).encode()))
    try:
        write_all(files)
    except OSError as exc:
        interrupts.check()
        return error_exit(PROG, exc, args.out or args.json)
    if show:
        print_results(sf, report)
    return exit_status(PROG, stream.damage, 'input damaged; fitted on the messages before it')


def print_results(sf: StreamFit, report: dict) -> None:
    """Print the fitted values, the likelihoods, the NIS check and the notes."""
    res, nis = sf.result, report['nis']
    for name, t, se in zip(res.names, res.theta, res.theta_stderr):
        kept = ' (not determined: not written)' if name in report['undetermined'] else ''
        print(f'{name} = {np.exp(t):.6g} (stderr {np.exp(t) * se:.3g}; log {t:.4f} +- '
              f'{se:.4f}){kept}')
    print(f'log-likelihood {report["log_likelihood"]:.3f} over {report["n"]} steps '
          f'(the parameter file\'s Q, R: {report["params_file"]["log_likelihood"]:.3f}); '
          f'NIS mean {nis["mean"]:.4f}, 95% band [{nis["band"][0]:.4f}, '
          f'{nis["band"][1]:.4f}] ({"consistent" if nis["consistent"] else "outside"}); '
          f'{report["gaps"]} gaps, {report["excluded_by_gate"]} gated')
    for note in sf.notes:
        print(f'{PROG}: note: {note}')


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(console_main)
