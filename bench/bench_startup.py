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
Benchmark: start-up and peak memory of the nodes against a minimal rclpy relay.

    python bench/bench_startup.py [--repeats 3] [--rss-seconds 60] [--rate 1000]
                                  [--jitter 0.01] [--plot docs/startup_rss.png]
                                  [--discovery fast|default]
                                  [--nodes estimator alignment alignment2]

A driver in this process publishes sensor_msgs/msg/Illuminance at `--rate` Hz (stamps on a
grid of 1 / rate, each moved by up to +-`--jitter` of the period with `--jitter`, or
exact) on the estimator's `measurement` and the alignment node's `intensity` topics, and
takes the first `estimate/predicted` of each process it starts.  Start-up is the wall
time from spawning the console script (`tskf_timescale_estimator`, `tskf_alignment`) or
the relay (bench/minimal_relay.py) to that first message (the alignment node's first
base command; `alignment2` is the alignment node with `-p axes:=2`, its two-axis
session), for each of:

- cache warm: numba's cache next to the sources holds the kernels (what ./run compiles);
- cache empty: NUMBA_CACHE_DIR is a new empty directory;
- read-only: the package's source tree is mounted read-only (a mount namespace of its
  own: `unshare --mount`, as root), numba's cache in NUMBA_CACHE_DIR (warmed beforehand,
  or empty), so nothing can be written next to the sources.

The nodes' kernels compiled ahead of time (tskf_ros.core.aot, built by ./run) are part of
the install: present in every set-up ($TSKF_AOT=off in this script's environment leaves
them out, the nodes then compile with numba in the background).

Two figures per start, from the same spawn: (a) spawn to the first estimate received
here, as above; (b) the process's own start, from marks it writes (bench/startup_marks.py
runs each command, the relay's too, with three public rclpy calls wrapped until their
first call): its time from spawn to its executor's first turn, plus its time from its
first input to its first publish() on the output, i.e. (a) without the wait for the
middleware's discovery in between; with its CPU time (all threads) up to that publish().

Discovery: with `--discovery fast` (the default) this process and every process it
starts read bench/fastdds_discovery.xml (FASTRTPS_DEFAULT_PROFILES_FILE), which makes
each participant announce itself every 0.1 s instead of every 3 s.  With Fast DDS's
default (`--discovery default`) a start next to this process's participant is found in
about 0.3 s or only at that participant's next periodic announcement, 2 to 3 s later,
for the relay as for the nodes (doc/benchmarks.md), and (a) is bimodal.

The cases alternate (relay, estimator, alignment, relay, ...) over `--repeats` rounds, on
the jittered stamps; medians are printed with their ratio to the relay's median in the
same set-up.  Then each process
runs `--rss-seconds` under the stream, with exact and with jittered stamps, and its peak
resident size (VmHWM) is printed against the relay's.  `--plot` writes both as a PNG.
"""

import argparse
from dataclasses import dataclass
import json
import os
from pathlib import Path
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from typing import Optional

import numpy as np
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.subscription import Subscription
from sensor_msgs.msg import Illuminance
from std_msgs.msg import Float64MultiArray

REPO = Path(__file__).resolve().parent.parent
RELAY = Path(__file__).resolve().parent / 'minimal_relay.py'
MARKS = Path(__file__).resolve().parent / 'startup_marks.py'
DISCOVERY_PROFILE = Path(__file__).resolve().parent / 'fastdds_discovery.xml'
PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')
PACKAGE = REPO / 'tskf_ros'
OUTPUT = 'estimate/predicted'
NODES = {'relay': 'measurement', 'estimator': 'measurement', 'alignment': 'intensity',
         'alignment2': 'intensity'}     # alignment2: the alignment node with axes 2
# the output whose first message ends the start-up: the estimator's first estimate; the
# alignment node publishes its estimates once tracking, its base command from the first
# sample (while acquiring) on
FIRST_OUTPUT = {'estimator': OUTPUT, 'alignment': 'base_position_controller/commands',
                'alignment2': 'base_position_controller/commands'}
DEADLINE = 60.0         # s: the longest wait for a first estimate (the kernels compile after it)


def command(node: str, output: str, marks: bool = False) -> list[str]:
    """
    Return the command line of a node (its console script) or the relay, output remapped.

    With marks, the same script runs under bench/startup_marks.py (the interpreter of
    the console script's shebang: this one).
    """
    if node == 'relay':
        cmd = [str(RELAY), NODES[node], output]
    else:
        name = {'estimator': 'timescale_estimator', 'alignment': 'alignment',
                'alignment2': 'alignment'}[node]
        script = shutil.which(f'tskf_{name}') or str(Path(sys.prefix) / 'lib' / 'tskf_ros'
                                                     / name)
        cmd = [script, '--ros-args', '-r', f'__node:=bench_{node}', '-r',
               f'{FIRST_OUTPUT[node]}:={output}'] + (['-p', 'axes:=2'] if node == 'alignment2'
                                                     else [])
    if marks:
        return [sys.executable, str(MARKS)] + cmd
    return [sys.executable] + cmd if node == 'relay' else cmd


def read_only(cmd: list[str]) -> list[str]:
    """Wrap a command so that it runs with the package's source tree mounted read-only."""
    mount = f'mount --bind -o ro {PACKAGE} {PACKAGE} && exec "$@"'
    return ['unshare', '--mount', 'sh', '-c', mount, 'sh'] + cmd


class Driver(Node):
    """Publish the stream on both input topics; note when the first estimate comes back."""

    def __init__(self, rate: float, jitter: float) -> None:
        super().__init__('bench_startup_driver')
        self.period, self.jitter = 1.0 / rate, jitter
        self.pubs = [self.create_publisher(Illuminance, topic, qos_profile_sensor_data)
                     for topic in sorted(set(NODES.values()))]
        self.first: Optional[float] = None
        self.received = 0
        self.runs = 0
        self.sub: Optional[Subscription] = None
        self.rng = np.random.default_rng(1)
        self.running = True
        self.thread = threading.Thread(target=self._publish, daemon=True)
        self.thread.start()

    def _on_output(self, msg: Float64MultiArray) -> None:
        if self.first is None:
            self.first = time.monotonic()
        self.received += 1

    def _publish(self) -> None:
        """Publish at the rate, in batches of 10 ms, stamps on the grid (+- jitter)."""
        msg = Illuminance()
        k, start = 0, time.time()
        while self.running:
            due = int((time.time() - start) / self.period)
            while k < due:
                t = start + (k + self.jitter * self.rng.uniform(-1, 1)) * self.period
                msg.header.stamp.sec = int(t)
                msg.header.stamp.nanosec = int((t - int(t)) * 1e9)
                msg.illuminance = 1.0 + 0.01 * np.sin(k * self.period)
                for pub in self.pubs:
                    pub.publish(msg)
                k += 1
            time.sleep(0.01)

    def listen(self) -> str:
        """Subscribe to a new output topic (the next process's); return its name."""
        if self.sub is not None:
            self.destroy_subscription(self.sub)
        self.runs += 1
        topic = f'/bench_startup/run{self.runs}'
        self.first, self.received = None, 0
        self.sub = self.create_subscription(Float64MultiArray, topic, self._on_output, 10)
        return topic


def vm_hwm_kib(pid: int) -> int:
    """Return a process's peak resident size (VmHWM), KiB."""
    with open(f'/proc/{pid}/status') as f:
        for line in f:
            if line.startswith('VmHWM:'):
                return int(line.split()[1])
    raise RuntimeError(f'no VmHWM for {pid}')


@dataclass
class Start:
    """One start: (a) spawn to the first estimate here, (b) the process's own start, s."""

    first_estimate: float
    own: float = float('nan')       # (ready - spawn) + (output - input), startup_marks.py
    cpu: float = float('nan')       # the process's CPU time up to its first output
    peak_kib: int = 0               # VmHWM after the hold


def run_one(driver: Driver, executor: SingleThreadedExecutor, node: str, env: dict, *,
            ro: bool = False, hold: float = 0.0, marks: bool = False) -> Start:
    """Start a node; return its Start (peak RSS after hold s more)."""
    output = driver.listen()
    cmd = command(node, output, marks)
    if ro:
        cmd = read_only(cmd)
    marks_file = tempfile.NamedTemporaryFile(prefix='tskf_bench_marks_', delete=False)
    marks_file.close()
    env = dict(env, BENCH_STARTUP_MARKS=marks_file.name, BENCH_STARTUP_INPUT=NODES[node],
               BENCH_STARTUP_OUTPUT=output)
    log = tempfile.TemporaryFile()
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=log,
                            start_new_session=True)
    try:
        while driver.first is None:
            executor.spin_once(timeout_sec=0.05)
            if proc.poll() is not None:
                log.seek(0)
                raise RuntimeError(f'{node} ended ({proc.returncode}): '
                                   f'{log.read().decode()[-2000:]}')
            if time.monotonic() - t0 > DEADLINE:
                raise RuntimeError(f'{cmd[0]}: no estimate in {DEADLINE} s')
        start = Start(driver.first - t0)
        end = time.monotonic() + hold
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        start.peak_kib = vm_hwm_kib(proc.pid)
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if os.environ.get('BENCH_STARTUP_LOGS'):
            log.seek(0)
            print(log.read().decode()[-3000:])
        log.close()
        text = Path(marks_file.name).read_text()
        os.unlink(marks_file.name)
    if marks:
        if not text:
            raise RuntimeError(f'{node}: no start-up marks written')
        m = json.loads(text)
        start.own = (m['ready'] - t0) + (m['output'] - m['input'])
        start.cpu = m['cpu']
    return start


def warm_cache(cache: str, env: dict) -> None:
    """Compile the kernels into a numba cache directory (what a first run leaves there)."""
    code = 'from tskf_ros.core import kalman, smoother; kalman.warm_up(); smoother.warm_up()'
    subprocess.run([sys.executable, '-c', code], env=dict(env, NUMBA_CACHE_DIR=cache),
                   check=True)


def startup_table(driver: Driver, executor: SingleThreadedExecutor, repeats: int,
                  ro_cache: str) -> tuple[dict, dict, dict]:
    """Measure the start-up of every node in every cache case: (a), (b) and CPU times."""
    env = dict(os.environ)
    env.pop('TSKF_JIT', None)
    cases = ['warm', 'empty', 'read-only warm', 'read-only empty']
    times: dict = {case: {node: [] for node in NODES} for case in cases}
    own: dict = {case: {node: [] for node in NODES} for case in cases}
    cpu: dict = {case: {node: [] for node in NODES} for case in cases}
    for r in range(repeats):
        for case in cases:
            for node in NODES:
                case_env = dict(env)
                empty = None
                if 'empty' in case:
                    empty = tempfile.mkdtemp(prefix='tskf_bench_numba_')
                    case_env['NUMBA_CACHE_DIR'] = empty
                elif case.startswith('read-only'):
                    case_env['NUMBA_CACHE_DIR'] = ro_cache
                try:
                    s = run_one(driver, executor, node, case_env,
                                ro=case.startswith('read-only'), marks=True)
                except RuntimeError as exc:     # a start that hung or failed: left out
                    print(f'  round {r + 1} {case:16s} {node:10s} left out: {exc}', flush=True)
                    continue
                finally:
                    if empty:
                        shutil.rmtree(empty, ignore_errors=True)
                times[case][node].append(s.first_estimate)
                own[case][node].append(s.own)
                cpu[case][node].append(s.cpu)
                print(f'  round {r + 1} {case:16s} {node:10s} {s.first_estimate:6.2f} s, '
                      f'own {s.own:5.2f} s, CPU {s.cpu:5.2f} s '
                      f'(load {os.getloadavg()[0]:.2f})', flush=True)
    return times, own, cpu


def rss_table(driver: Driver, executor: SingleThreadedExecutor, seconds: float,
              jitter: float, jit: str) -> dict:
    """Run each node `seconds` under the stream, exact then jittered stamps; peak RSS MiB."""
    env = dict(os.environ, TSKF_JIT=jit)
    peaks: dict = {}
    for stamps, j in (('exact', 0.0), ('jittered', jitter)):
        driver.jitter = j
        for node in NODES:
            hwm = run_one(driver, executor, node, env, hold=seconds).peak_kib
            peaks.setdefault(stamps, {})[node] = hwm / 1024
            print(f'  {stamps:8s} {node:10s} peak RSS {hwm / 1024:6.1f} MiB, '
                  f'{driver.received} estimates back (load {os.getloadavg()[0]:.2f})',
                  flush=True)
    driver.jitter = jitter
    return peaks


def plot(path: Path, times: dict, peaks: dict, title_note: str) -> None:
    """Write start-up (median s) and peak RSS (MiB) of each node against the relay."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    nodes = list(NODES)
    width = 0.8 / len(nodes)
    cases = list(times)
    for i, node in enumerate(nodes):
        med = [statistics.median(times[c][node]) for c in cases]
        ax1.bar(np.arange(len(cases)) + (i - (len(nodes) - 1) / 2) * width, med, width,
                label=node)
    relay = [statistics.median(times[c]['relay']) for c in cases]
    ax1.scatter(np.arange(len(cases)), [1.5 * r for r in relay], marker='_', s=900,
                color='k', label='goal: 1.5 x relay', zorder=3)
    ax1.set_xticks(np.arange(len(cases)), [c.replace('read-only ', 'read-only\n')
                                           for c in cases])
    ax1.set_ylabel('spawn to first estimate (s), median')
    ax1.set_xlabel('numba cache / install tree')
    ax1.set_title('Start-up')
    ax1.set_ylim(0, ax1.get_ylim()[1] * 1.4)
    ax1.legend(fontsize=8, ncol=2, loc='upper left')
    stamps = list(peaks)
    for i, node in enumerate(nodes):
        ax2.bar(np.arange(len(stamps)) + (i - (len(nodes) - 1) / 2) * width,
                [peaks[s][node] for s in stamps], width, label=node)
    ax2.scatter(np.arange(len(stamps)), [2 * peaks[s]['relay'] for s in stamps], marker='_',
                s=900, color='k', label='goal: 2 x relay', zorder=3)
    ax2.set_xticks(np.arange(len(stamps)), [f'{s} stamps' for s in stamps])
    ax2.set_ylabel('peak resident size VmHWM (MiB)')
    ax2.set_xlabel('input stamps')
    ax2.set_title('Peak memory under the stream')
    ax2.set_ylim(0, ax2.get_ylim()[1] * 1.4)
    ax2.legend(fontsize=8, ncol=2, loc='upper left')
    fig.suptitle(f'tskf_ros nodes against a minimal rclpy relay ({title_note})')
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f'wrote {path}')


def main() -> None:
    """Run the benchmark; print the figures and their ratios to the relay."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--rss-seconds', type=float, default=60.0,
                        help='seconds each process runs under the stream (0: no RSS table)')
    parser.add_argument('--rate', type=float, default=1000.0, help='Hz')
    parser.add_argument('--jitter', type=float, default=0.01,
                        help='stamp jitter, fraction of the period (the jittered cases)')
    parser.add_argument('--plot', type=Path, default=None, help='PNG to write')
    parser.add_argument('--json', type=Path, default=None, help='write the figures here')
    parser.add_argument('--jit', default='background', choices=['background', 'off', 'wait'],
                        help="the nodes' $TSKF_JIT in the RSS runs (default: the nodes' own)")
    parser.add_argument('--nodes', nargs='+', default=list(NODES), choices=list(NODES))
    parser.add_argument('--discovery', default='fast', choices=['fast', 'default'],
                        help='fast: every participant (this one, the relay, the nodes) '
                        f'reads {DISCOVERY_PROFILE.name} (announcements every 0.1 s); '
                        "default: Fast DDS's own (every 3 s)")
    parser.add_argument('--replot', type=Path, default=None,
                        help='only redraw --plot from a --json file of an earlier run')
    args = parser.parse_args()
    if args.replot:
        saved = json.loads(args.replot.read_text())
        plot(args.plot, saved['startup'], saved['peak_rss_mib'], saved['note'])
        return
    for node in set(NODES) - set(args.nodes) - {'relay'}:
        del NODES[node]
    if os.geteuid() != 0 or not shutil.which('unshare'):
        sys.exit('bench_startup: the read-only cases need root and unshare')
    for variable in PROFILE_VARIABLES:
        if args.discovery == 'fast':
            os.environ[variable] = str(DISCOVERY_PROFILE)   # here and in every child
        else:
            os.environ.pop(variable, None)
    print(f'{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}; '
          f'{args.rate:g} Hz, stamp jitter +-{args.jitter:.0%} of the period; '
          f'discovery {args.discovery}')
    rclpy.init()
    driver = Driver(args.rate, args.jitter)
    executor = SingleThreadedExecutor()
    executor.add_node(driver)
    ro_cache = tempfile.mkdtemp(prefix='tskf_bench_numba_ro_')
    try:
        warm_cache(ro_cache, dict(os.environ))
        times, own, cpu = startup_table(driver, executor, args.repeats, ro_cache) \
            if args.repeats > 0 else ({}, {}, {})
        peaks = rss_table(driver, executor, args.rss_seconds, args.jitter, args.jit) \
            if args.rss_seconds > 0 else {}
    finally:
        driver.running = False
        shutil.rmtree(ro_cache, ignore_errors=True)
        executor.shutdown()
        driver.destroy_node()
        rclpy.try_shutdown()
    for title, table in (('(a) spawn to first estimate', times),
                         ("(b) the process's own start", own),
                         ('CPU time to the first output', cpu)):
        if not table:
            continue
        print(f'\n{title}, median of {args.repeats} (ratio to the relay of the same case; '
              'goal <= 1.5)')
        print(f'{"case":18s}' + ''.join(f'{n:>22s}' for n in NODES))
        pooled = {n: [t for row in table.values() for t in row[n]] for n in NODES}
        for case, row in list(table.items()) + [('all starts', pooled)]:
            relay = statistics.median(row['relay'])
            cells = [f'{statistics.median(row[n]):6.2f} s '
                     f'({statistics.median(row[n]) / relay:4.2f}x)' for n in NODES]
            print(f'{case:18s}' + ''.join(f'{c:>22s}' for c in cells))
    if peaks:
        print(f'\npeak RSS over {args.rss_seconds:g} s at {args.rate:g} Hz, TSKF_JIT={args.jit} '
              '(ratio to the relay; goal <= 2)')
        for stamps, row in peaks.items():
            cells = [f'{row[n]:6.1f} MiB ({row[n] / row["relay"]:4.2f}x)' for n in NODES]
            print(f'{stamps:18s}' + ''.join(f'{c:>22s}' for c in cells))
    print(f'load average at the end {os.getloadavg()[0]:.2f}')
    note = f'{args.rate:g} Hz, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.1f}'
    if args.json:
        args.json.write_text(json.dumps({'startup': times, 'own_startup': own,
                                         'cpu_to_first_output': cpu, 'peak_rss_mib': peaks,
                                         'discovery': args.discovery, 'note': note},
                                        indent=1))
    if args.plot and peaks and times:
        plot(args.plot, times, peaks, note)


if __name__ == '__main__':
    main()
