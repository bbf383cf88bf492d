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

"""plot_bag: a bag as PNGs, as Cai et al. Fig. 2 (estimator) and Solanki et al. Fig. 8."""

import argparse
import os
from pathlib import Path
import sys
import tempfile
from typing import Optional

import matplotlib
import numpy as np

from tskf_ros.bag.bag_errors import check_exists, run_main
from tskf_ros.bag.message_types import BagTypeError
from tskf_ros.bag.reader import BagError, BagReader, error_exit, exit_status
from tskf_ros.bag.replay.loop import replay
from tskf_ros.bag.replay.sinks import SMOOTHED_TOPIC
from tskf_ros.messages import alignment_interface as aligner
from tskf_ros.messages.estimator_interface import (BAG_OUTPUT_TOPICS, BAG_TRUTH_TOPIC,
                                                   load_config, ParamsError)

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402, I100, I202
from tskf_ros.tools.plot_estimator import (ESTIMATE, estimator_figure,  # noqa: E402, I100
                                           POWER, TRUTH)
from tskf_ros.tools.plot_rows import first, stream  # noqa: E402, I100
from tskf_ros.tools import plot_alignment  # noqa: E402, I100
from tskf_ros.tools import plot_pan_tilt as pan_tilt  # noqa: E402, I100
from tskf_ros.tools.plot_pan_tilt import is_pan_tilt_estimate  # noqa: E402, I100

PROG = 'plot_bag'
PREDICTED, CORRECTED = BAG_OUTPUT_TOPICS['predicted'], BAG_OUTPUT_TOPICS['corrected']
# a two-axis run as tskf_make_sample_bags and the simulator's default namespace write it
PAN_TILT_ESTIMATE, PAN_TILT_TRUTH = '/pan_tilt/estimate', '/pan_tilt/truth'
# a one-axis run as tskf_make_sample_bags writes it
ALIGNMENT_ESTIMATE, ALIGNMENT_TRUTH = '/alignment/estimate', '/alignment/truth'


class PlotDamageError(BagError):
    """The bag is damaged and nothing before the damage can be plotted."""

    def __init__(self, damage) -> None:
        super().__init__(str(damage))
        self.damage = damage


class Plotted(list):
    """The PNGs written (a list of paths) and the damage met while reading, if any."""

    damage = None


def _require(reader: BagReader, data: dict, topics) -> None:
    """Raise PlotDamageError or BagError unless every topic of `topics` has messages."""
    empty = [t for t in topics if not len(data.get(t, ()))]
    if empty:
        if reader.damage is not None:
            raise PlotDamageError(reader.damage)
        raise BagError(f'{reader.path}: no messages on {", ".join(empty)}: nothing to plot')


def plot(bag: Path, out: Path, *, params_file: Optional[Path] = None,
         topic: Optional[str] = None, log=print) -> list:
    """
    Write the PNGs of a bag into `out`; return their paths (a Plotted list).

    The result's `damage` is set if the bag was damaged (what came before is plotted);
    PlotDamageError if nothing before the damage can be plotted.
    """
    reader = BagReader(bag)
    written = Plotted()
    if aligner.BAG_OUTPUT_TOPICS['command'] in reader.topics:
        intensity = topic or next((t for t in (aligner.BAG_INPUT_TOPIC, '/photodiode')
                                   if t in reader.topics), aligner.BAG_INPUT_TOPIC)
        corrected = aligner.BAG_OUTPUT_TOPICS['corrected']
        data, names = _alignment_rows(reader, corrected, intensity)
        if not len(data.get(corrected, ())):
            if reader.damage is not None:
                raise PlotDamageError(reader.damage)
            raise BagError(f'{bag}: no EKF estimates on {corrected} (algorithm is not ekf?): '
                           'nothing to plot')
        written.damage = reader.damage
        out.mkdir(parents=True, exist_ok=True)
        fig = plot_alignment.alignment_figure(
            data[corrected], f'{bag.name}: alignment node replayed offline (open loop: the '
            'commands did not move the recorded receiver)', truth=data[ALIGNMENT_TRUTH],
            names=names, intensity=data[intensity], recorded=data[ALIGNMENT_ESTIMATE],
            label='x(t|t) of the replay (open loop)')
        written.append(_save(fig, out / 'alignment.png'))
        return written
    if PAN_TILT_ESTIMATE in reader.topics:
        intensity = topic or '/photodiode'
        head = first(reader, PAN_TILT_ESTIMATE)
        if head is not None and not is_pan_tilt_estimate(head):
            raise BagError(f'{bag}: {PAN_TILT_ESTIMATE} is not a two-axis alignment estimate '
                           '(the states [x1, d_c, d_e, b_c, b_e]): nothing to plot')
        kinds = {PAN_TILT_ESTIMATE: pan_tilt.ESTIMATE, PAN_TILT_TRUTH: pan_tilt.TRUTH,
                 intensity: POWER}
        data = stream(reader, {t: k for t, k in kinds.items() if t in reader.topics})
        _require(reader, data, [PAN_TILT_ESTIMATE])
        written.damage = reader.damage
        out.mkdir(parents=True, exist_ok=True)
        fig = pan_tilt.pan_tilt_figure(
            data[PAN_TILT_ESTIMATE], data.get(PAN_TILT_TRUTH, np.zeros((0, 4))),
            data.get(intensity, np.zeros((0, 2))),
            f'{bag.name}: two-axis (pan-tilt) conical-scan EKF alignment')
        written.append(_save(fig, out / 'alignment.png'))
        return written
    if ALIGNMENT_ESTIMATE in reader.topics:
        data, names = _alignment_rows(reader, ALIGNMENT_ESTIMATE, '/photodiode')
        _require(reader, data, [ALIGNMENT_ESTIMATE])
        written.damage = reader.damage
        out.mkdir(parents=True, exist_ok=True)
        fig = plot_alignment.alignment_figure(
            data[ALIGNMENT_ESTIMATE], f'{bag.name}: scanning-EKF alignment (Fig. 8 style)',
            truth=data[ALIGNMENT_TRUTH], names=names, intensity=data['/photodiode'])
        written.append(_save(fig, out / 'alignment.png'))
        return written
    config = load_config(params_file)
    model = config.session.model
    C, D = float(model.C[0, 0]), float(model.D[0]) if model.D is not None else 0.0
    # one row of floats per message, streamed (a bag of 1e7 estimates is 320 MB of rows)
    if CORRECTED in reader.topics:
        meas_topic = topic or '/received_power'
        data = stream(reader, _rows(reader, meas_topic))
        _require(reader, data, [PREDICTED, CORRECTED])
        written.damage = reader.damage
    else:
        log(f'{bag}: no estimates in the bag: running the estimator offline first')
        # into a bag of its own, then read as one (memory bounded at any length)
        with tempfile.TemporaryDirectory(prefix='tskf_plot_bag_') as scratch:
            res = replay(bag, Path(scratch) / 'estimated', params_file=params_file,
                         topic=topic, diagnostics=False, log=log)
            estimated = BagReader(Path(scratch) / 'estimated')
            meas_topic = res.topic if res.msgtype == 'sensor_msgs/msg/Illuminance' else ''
            data = stream(estimated, _rows(estimated, meas_topic))
        written.damage = res.damage
        if not len(data.get(CORRECTED, ())) or not len(data.get(PREDICTED, ())):
            if res.damage is not None:
                raise PlotDamageError(res.damage)
            raise BagError(f'{bag}: too few samples on {res.topic} for an estimate: '
                           'nothing to plot')
    measurement = data.get(meas_topic, np.zeros((0, 2)))
    out.mkdir(parents=True, exist_ok=True)
    kinds = (('predictor', PREDICTED), ('corrected', CORRECTED), ('smoothed', SMOOTHED_TOPIC))
    series = {kind: data[t] for kind, t in kinds if len(data.get(t, ()))}
    fig = estimator_figure(series, measurement, data.get(BAG_TRUTH_TOPIC, np.zeros((0, 2))),
                           C, D, f'{bag.name}: time-scale filter, {model.name} model')
    written.append(_save(fig, out / 'estimator.png'))
    return written


def _alignment_rows(reader: BagReader, estimates: str, intensity: str) -> tuple:
    """Return a one-axis bag's rows ({topic: array}, every topic present) and truth names."""
    head = first(reader, ALIGNMENT_TRUTH)
    names = list(head.name) if head is not None else []
    kinds = {estimates: plot_alignment.ESTIMATE, ALIGNMENT_ESTIMATE: plot_alignment.ESTIMATE,
             ALIGNMENT_TRUTH: plot_alignment.truth_kind(names), intensity: POWER}
    data = stream(reader, {t: k for t, k in kinds.items() if t in reader.topics})
    for topic, kind in kinds.items():
        data.setdefault(topic, np.zeros((0, kind.width)))
    return data, names


def _rows(reader: BagReader, measurement: str) -> dict:
    """Return the estimator figure's rows for the topics the bag has."""
    rows = {PREDICTED: ESTIMATE, CORRECTED: ESTIMATE, SMOOTHED_TOPIC: ESTIMATE,
            measurement: POWER, BAG_TRUTH_TOPIC: TRUTH}
    return {t: row for t, row in rows.items() if t in reader.topics}


def _save(fig, path: Path) -> Path:
    tmp = path.with_name(f'.{path.name}.partial.png')
    try:
        fig.savefig(tmp, dpi=110, bbox_inches='tight')
        tmp.replace(path)
    except BaseException:       # an error or Ctrl-C: no half-written file
        tmp.unlink(missing_ok=True)
        raise
    finally:
        plt.close(fig)
    return path


def main(argv: Optional[list] = None) -> int:
    """Run the command line; return the exit status."""
    parser = argparse.ArgumentParser(prog=PROG, description='Plot a bag into PNGs.')
    parser.add_argument('bag', type=Path)
    parser.add_argument('--out', type=Path, default=Path('results') / 'plots')
    parser.add_argument('--params-file', type=Path, help='estimator parameters (for C, D '
                        'and, on a raw bag, the estimator)')
    parser.add_argument('--topic', help='measurement topic (default /received_power)')
    args = parser.parse_args(argv)
    problem = _check_paths(args.bag, args.out, args.params_file)
    if problem:
        print(f'{PROG}: error: {problem}', file=sys.stderr)
        return 1
    try:
        paths = plot(args.bag, args.out, params_file=args.params_file, topic=args.topic,
                     log=lambda s: print(f'{PROG}: {s}'))
    except PlotDamageError as exc:
        return exit_status(PROG, exc.damage, 'bag damaged, nothing before the damage to plot')
    except (BagError, ParamsError, BagTypeError, OSError) as exc:
        return error_exit(PROG, exc, args.out)
    for p in paths:
        print(f'{PROG}: wrote {p}')
    return exit_status(PROG, paths.damage, 'bag damaged; plotted what came before')


def _check_paths(bag: Path, out: Path, params: Optional[Path]) -> str:
    """Return a one-line problem with the paths, or ''."""
    try:
        check_exists(bag)
    except BagError as exc:
        return str(exc)
    if params is not None and not params.is_file():
        return f'{params}: no such parameters file'
    if out.exists() and not out.is_dir():
        return f'{out}: exists and is not a directory'
    parent = out
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        return f'{out}: {parent} is not a directory'
    if not os.access(parent, os.W_OK | os.X_OK):
        return f'{out}: cannot write in {parent} (permission denied)'
    return ''


def console_main() -> None:
    """Entry point of the console script (Ctrl-C: one line, exit 130)."""
    sys.exit(run_main(PROG, main))


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(console_main)
