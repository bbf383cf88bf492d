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

"""The live demo: the OWC (Cai et al. IV-C) and LED pipelines as processes over DDS."""

import argparse
from dataclasses import dataclass
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import threading
import time
from types import FrameType
from typing import Optional, Union

import numpy as np

from tskf_ros.experiments import arguments
from tskf_ros.experiments.demo_summary import format_summary, summarise, Summary
from tskf_ros.led import PAPER_DT, TRACKING_ANGLE
from tskf_ros.tools.console import start_held

LED_NAMESPACE = '/led'
# the largest ROS_DOMAIN_ID of ROS 2 on Linux (its ports must stay below 65536)
MAX_DOMAIN_ID = 232
LED_DT = PAPER_DT          # s: the LED link's sample period (config/led_link_simulator.yaml)
# s the demo's children have, together, to end after its SIGINT before they are killed
# (a node ends within 5 s of a signal in any state: test/nodes/test_node_shutdown.py)
STOP_TIMEOUT = 10.0


def config_dir() -> Path:
    """config/ of the source tree, else the installed package's share/tskf_ros/config."""
    here = Path(__file__).resolve().parents[2] / 'config'
    if here.is_dir():
        return here
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('tskf_ros')) / 'config'


def bags_dir() -> Path:
    """bags/ of the source tree, else the installed package's share/tskf_ros/bags."""
    here = Path(__file__).resolve().parents[2] / 'bags'
    if here.is_dir():
        return here
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('tskf_ros')) / 'bags'


def replay_sample_bag(out: Path) -> int:
    """Replay the Cai T_d sample bag through the estimator offline and plot the result."""
    from tskf_ros.bag.replay import cli as offline_replay
    from tskf_ros.tools import plot_bag
    bag = bags_dir() / 'owc_cai_td_1hz'
    params = config_dir() / 'owc_estimator.yaml'
    estimated = out / 'owc_cai_td_1hz_estimated'
    print(f'replaying the sample bag {bag.name} through the estimator (no DDS) -> {estimated}',
          flush=True)
    if (estimated / 'metadata.yaml').is_file() and {
            f.suffix for f in estimated.iterdir()} <= {'.yaml', '.mcap'}:
        # the demo's own output of an earlier run: a bag written before the writer marked
        # its bags would be refused by --overwrite, which replaces only marked ones
        shutil.rmtree(estimated)
    rc = offline_replay.main([str(bag), str(estimated), '--params-file', str(params),
                              '--overwrite'])
    if rc == 0:
        rc = plot_bag.main([str(estimated), '--out', str(out), '--params-file', str(params)])
    return rc


class Children:
    """
    The demo's child processes, each the leader of its own process group, and its monitors.

    A Ctrl-C reaches the demo alone (a terminal's goes to the foreground group, which no
    longer holds the children), and `stop` passes one SIGINT on to each child's group, as
    a Ctrl-C to that child alone would be: the same end whether the signal went to the
    demo's group or to the demo process only, and no child signalled twice mid-shutdown.
    Each child starts with SIGINT held until its console runner takes it (start_held): a
    stop while a child still starts (the interpreter, its imports) ends it quietly too.
    """

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen] = []
        self.monitors: list[dict] = []      # the LED loop's monitor (start_alignment)
        self.lock = threading.Lock()
        self.stopping = False

    def start(self, cmd: list) -> Optional[subprocess.Popen]:
        """Start cmd in its own process group; None once stop() has begun (nothing started)."""
        with self.lock:
            if self.stopping:
                return None
            proc = start_held(cmd, env=dict(os.environ), process_group=0)
            self.procs.append(proc)
            return proc

    def stop(self, procs: Optional[list] = None) -> None:
        """SIGINT to the children (all, or procs) still running; kill those that hang."""
        with self.lock:
            if procs is None:
                self.stopping = True
            procs = list(self.procs if procs is None else procs)
        for p in procs:
            if p.poll() is None:
                _signal_group(p, signal.SIGINT)
        deadline = time.monotonic() + STOP_TIMEOUT
        for p in procs:
            try:
                p.wait(timeout=max(deadline - time.monotonic(), 0.0))
            except subprocess.TimeoutExpired:
                _signal_group(p, signal.SIGKILL)
                p.wait()


def _signal_group(proc: subprocess.Popen, sig: int) -> None:
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:      # ended (and its group with it) meanwhile
        pass


def node_command(module: str, params_file: Path,
                 **params: Union[bool, int, float, str]) -> list:
    """
    Return the node's console-script command `--ros-args --params-file ... -p k:=v`.

    Run as the installed executable runs it, a node that takes the terminal's Ctrl-C while
    it still imports ends quietly too (`python -m` would print that traceback).
    """
    cmd = [sys.executable, '-c', f'from tskf_ros.tools.console import {module}; {module}()',
           '--ros-args', '--params-file', str(params_file)]
    for k, v in params.items():
        cmd += ['-p', f'{k}:={str(v).lower() if isinstance(v, bool) else v}']
    return cmd


def run_processes(args: argparse.Namespace, children: Children) -> Summary:
    """Start both nodes as processes, collect in this process, stop them; summarise."""
    from tskf_ros.tools.demo_collector import collect

    cfg = config_dir()
    time_factor = 1.0 / args.duration_scale
    procs = []

    def start_simulator() -> None:
        procs.append(children.start(node_command(
            'power_meter_simulator', cfg / 'power_meter_simulator.yaml',
            rate=float(args.rate), seed=args.seed, duration=float(args.duration),
            time_factor=float(time_factor), start_time=1.0, wait_for_subscribers=2,
            blockage=args.blockage, drop_probability=float(args.drop_probability))))

    # the estimator's neutral `measurement` is the power meter's received_power here
    procs.append(children.start(node_command(
        'timescale_estimator', cfg / 'owc_estimator.yaml', transition=args.transition)
        + ['-r', 'measurement:=received_power']))
    try:
        samples = int(round(args.duration * args.rate))
        timeout = args.duration * args.duration_scale * 3 + 30
        record = collect(samples, timeout=timeout, on_ready=start_simulator)
    finally:
        children.stop([p for p in procs if p is not None])
    return summarise(record, period=1.0 / args.rate)


@dataclass
class AlignmentSummary:
    """The LED alignment loop's figures (Solanki et al.): tracking by angle."""

    algorithm: str
    samples: int
    delivered: int
    commands: int
    tracking: float            # % of samples with |phi| <= 15 deg
    tracking_converged: float  # the same from 2 s on
    worst: float               # max |phi| (deg) from 2 s on
    diagnostics: dict


def start_alignment(args: argparse.Namespace, children: Children) -> dict:
    """
    Start the LED loop (led_link_simulator + alignment in /led) beside the estimator demo.

    The monitor runs on its own thread and context; `finish_alignment` joins it, and
    `stop_alignment` ends it at once (a Ctrl-C): a thread still inside rclpy when the
    interpreter exits aborts the process ("terminate called without an active exception").
    """
    from tskf_ros.tools.alignment_monitor import monitor

    cfg = config_dir()
    ns = ['-r', f'__ns:={LED_NAMESPACE}']
    samples = int(round(args.led_duration / LED_DT))
    procs = [children.start(node_command(
        'alignment', cfg / 'alignment.yaml', algorithm=args.led_algorithm,
        **{'diagnostic_updater.period': 0.25}) + ns)]
    out: dict = {'procs': procs, 'args': args, 'samples': samples, 'children': children,
                 'stop': threading.Event()}

    def start_simulator() -> None:
        procs.append(children.start(node_command(
            'led_link_simulator', cfg / 'led_link_simulator.yaml', seed=args.seed,
            beta=float(args.led_beta), noise=float(args.led_noise),
            blockage=args.led_blockage, duration=float(args.led_duration),
            time_factor=float(args.led_time_factor), start_time=1.0,
            wait_for_subscribers=2) + ns))

    def run() -> None:
        try:
            out['record'] = monitor(samples, namespace=LED_NAMESPACE,
                                    timeout=args.led_duration / args.led_time_factor * 3 + 30,
                                    on_ready=start_simulator, stop=out['stop'])
        except Exception as exc:  # noqa: B902 - reported by finish_alignment
            out['error'] = exc

    out['thread'] = threading.Thread(target=run, name='alignment-monitor')
    children.monitors.append(out)
    out['thread'].start()
    return out


def stop_alignment(handle: dict) -> None:
    """End the LED loop's monitor thread now (its waits return); its processes stay."""
    handle['stop'].set()
    handle['thread'].join()


def finish_alignment(handle: dict) -> AlignmentSummary:
    """Wait for the LED loop, stop its processes, and summarise its tracking."""
    handle['thread'].join()
    handle['children'].stop([p for p in handle['procs'] if p is not None])
    if 'error' in handle:
        raise handle['error']
    r = handle['record']
    phi = np.array([r.phi[k] for k in sorted(r.phi)])
    start = int(round(2.0 / LED_DT))
    tail = np.abs(phi[start:])
    return AlignmentSummary(
        algorithm=handle['args'].led_algorithm, samples=phi.size, delivered=len(r.intensity),
        commands=r.commands, tracking=100.0 * float(np.mean(np.abs(phi) <= TRACKING_ANGLE)),
        tracking_converged=100.0 * float(np.mean(tail <= TRACKING_ANGLE)) if tail.size
        else float('nan'), worst=float(tail.max()) if tail.size else float('nan'),
        diagnostics=r.diagnostics)


def format_alignment(s: AlignmentSummary, args: argparse.Namespace) -> str:
    """Format the alignment loop's summary line(s)."""
    d = s.diagnostics
    return (f'alignment ({s.algorithm}, beta {args.led_beta:g} deg/s, noise '
            f'{args.led_noise:g} V, dropouts: {args.led_blockage}): tracking '
            f'{s.tracking:.1f}% of {s.samples} samples (|phi| <= {TRACKING_ANGLE:g} deg), '
            f'{s.tracking_converged:.1f}% from 2 s on (max |phi| {s.worst:.1f} deg); '
            f'{s.delivered} intensities, {s.commands} base commands, '
            f'gaps {d.get("Gaps", "?")}, largest mu {float(d.get("mu max", "nan")):g}')


def make_parser() -> argparse.ArgumentParser:
    """Return the demo's argument parser."""
    parser = argparse.ArgumentParser(
        prog='python -m tskf_ros.experiments.demo', description=__doc__.split('\n')[0],
        epilog="`./run demo [ARG...]` is this demo with --reproduce [ARG...]: the papers' "
        'numerical examples into results/ first (ARG... go to python -m '
        'tskf_ros.experiments.reproduce; `./run demo --help` prints this). Ctrl-C in any '
        'phase stops every process the demo started, exit status 130.')
    number = arguments.number
    seconds = number(0.0, 86_400.0, open_low=True)      # of stamped data: at most a day
    parser.add_argument('--duration', type=seconds, default=300.0,
                        help='seconds of stamped data (default: 300, as Cai IV-C)')
    parser.add_argument('--duration-scale', type=number(0.0, 100.0, open_low=True),
                        default=0.05,
                        help='wall time per stamped second (default 0.05: 300 s in 15 s)')
    parser.add_argument('--rate', type=number(0.0, 10_000.0, open_low=True), default=1.0,
                        help='samples per second')
    parser.add_argument('--seed', type=arguments.seed, default=0)
    parser.add_argument('--transition', choices=('euler', 'exact'), default='euler')
    parser.add_argument('--blockage', choices=('none', 'bernoulli', 'gilbert_elliott'),
                        default='none')
    parser.add_argument('--drop-probability', type=number(0.0, 1.0), default=0.0)
    parser.add_argument('--domain-id', type=arguments.count(0, MAX_DOMAIN_ID), default=None,
                        help='ROS_DOMAIN_ID for all processes (default: from the '
                        'environment, else derived from the process id)')
    parser.add_argument('--led-duration', type=seconds, default=60.0,
                        help='seconds of stamped data of the LED alignment loop (default 60)')
    parser.add_argument('--led-time-factor', type=number(0.0, 1000.0, open_low=True),
                        default=4.0,
                        help='the LED loop plays this many times faster than its stamps')
    parser.add_argument('--led-algorithm', choices=('ekf', 'hill_climbing', 'three_point'),
                        default='ekf')
    parser.add_argument('--led-beta', type=number(-1000.0, 1000.0), default=1.2,
                        help='deg/s (Fig. 8: 1.2)')
    parser.add_argument('--led-noise', type=number(0.0, 100.0), default=0.2,
                        help='V (R_sys: 0.2)')
    parser.add_argument('--led-blockage', choices=('none', 'bernoulli', 'gilbert_elliott'),
                        default='none')
    parser.add_argument('--out', type=Path, default=Path('results'),
                        help='the replayed sample bag and its plot go to OUT/bag/ '
                             '(default: results/)')
    parser.add_argument('--no-bag', action='store_true',
                        help='skip replaying the sample bag')
    parser.add_argument('--no-alignment', action='store_true',
                        help='run the estimator demo only')
    parser.add_argument('--reproduce', nargs=argparse.REMAINDER, metavar='ARG',
                        help='first run python -m tskf_ros.experiments.reproduce --out '
                        'results/ ARG... (every argument after --reproduce goes there)')
    return parser


def parse_args(argv: Optional[list] = None) -> argparse.Namespace:
    """Command line of the demo (`--reproduce -h` is the demo's own --help too)."""
    parser = make_parser()
    args = parser.parse_args(argv)
    if args.reproduce is not None and {'-h', '--help'} & set(args.reproduce):
        parser.print_help()
        parser.exit(0)
    return args


def run_reproduce(extra: list, children: Children) -> int:
    """Run the papers' numerical examples into results/ as a child process; its status."""
    cmd = ['--out', 'results/', *extra]
    print(f'demo: python -m tskf_ros.experiments.reproduce {" ".join(cmd)}', flush=True)
    proc = children.start([sys.executable, '-c', 'from tskf_ros.tools.console import '
                           'reproduce; reproduce()', *cmd])
    return 0 if proc is None else proc.wait()


def where_to_look(args: argparse.Namespace) -> str:
    """Return the three lines that end the demo: where its results are."""
    figures = ("results/: the papers' figures (a PNG and a JSON per run), explained in "
               'doc/papers_reproduced.md' if args.reproduce is not None else
               "the papers' figures: `./run demo` (or python -m "
               'tskf_ros.experiments.reproduce) writes them into results/')
    bag = (f'{args.out / "bag"}/: the sample bag replayed through the estimator and its '
           'plot (estimator.png)' if not args.no_bag else
           'the sample bags in bags/: tskf_replay_offline and tskf_plot_bag (doc/bags.md)')
    return '\n'.join([
        f'where to look: {figures}',
        f'               {bag}',
        '               the numbers above are the live run over DDS; the nodes, topics and '
        'parameters: doc/nodes/ (or ./run docs)'])


def _interrupt(signum: int, frame: Optional[FrameType]) -> None:
    raise KeyboardInterrupt


def main(argv: Optional[list] = None) -> int:
    """Run the demo and print the summary; a Ctrl-C or SIGTERM stops every child first."""
    args = parse_args(argv)
    children = Children()
    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _interrupt) if main_thread else None
    try:
        return _run(args, children)
    finally:
        if main_thread:     # the cleanup itself is not interrupted
            before = signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
        for handle in children.monitors:
            stop_alignment(handle)
        children.stop()
        if main_thread:
            signal.signal(signal.SIGINT, before)
            signal.signal(signal.SIGTERM, previous)


def _run(args: argparse.Namespace, children: Children) -> int:
    if args.reproduce is not None:
        rc = run_reproduce(args.reproduce, children)
        if rc:
            return rc
    # every process of the demo talks only on this machine and in one domain
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    if args.domain_id is not None:
        os.environ['ROS_DOMAIN_ID'] = str(args.domain_id)
    os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 1))
    print(f'demo: {args.duration:g} s at {args.rate:g} Hz played in about '
          f'{args.duration * args.duration_scale:g} s, ROS_DOMAIN_ID='
          f'{os.environ["ROS_DOMAIN_ID"]}, seed {args.seed}', flush=True)
    print(f'demo: to watch it live in Foxglove (no ROS installation needed), run '
          f'`ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]} ./run shell -c tskf_foxglove_bridge` '
          'in another terminal and open ws://localhost:8765 in Foxglove with the layout '
          'config/foxglove_owc_live.json', flush=True)
    led = None if args.no_alignment else start_alignment(args, children)
    summary = run_processes(args, children)
    print(format_summary(summary), flush=True)
    if led is not None:
        print(format_alignment(finish_alignment(led), args), flush=True)
    rc = 0 if args.no_bag else replay_sample_bag(args.out / 'bag')
    if rc == 0:
        print(where_to_look(args), flush=True)
    return rc


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
