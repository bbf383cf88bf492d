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
Signals to node processes under a flowing input: each must end within a bound.

Shared by test/nodes/test_node_shutdown.py (the slow test) and a run by hand:

    ./run shell -c 'python test/nodes/shutdown_storm.py timescale_estimator 50'

Each run starts the node (python -m tskf_ros.nodes.<module>, through the console's
runner as the console scripts do), sends SIGINT or SIGTERM at a random moment (half
while it starts, half once it logged that it runs), and waits at most BOUND seconds for
it to end; a node still alive then is a hang: its threads' stacks are taken with gdb
(if there is one) and it is killed.  The flowing input: this process publishes
Illuminance on `measurement` and `intensity` at about RATE Hz.
"""

from dataclasses import dataclass, field
import os
from pathlib import Path
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Optional

REPO = Path(__file__).resolve().parents[2]
BOUND = 5.0             # s: a node ends within this after SIGINT or SIGTERM
START_TIMEOUT = 60.0    # s: a bound on a start on a loaded machine, never a result
RATE = 500.0            # Hz of the input published to the estimator and the aligner
SIM_METER = ['-p', f'backend:={REPO}/config/pm100_sim.yaml@sim']
# each node, its arguments (one set drawn per run: the states it may be in), and the
# line it logs once it runs
NODES = {
    'timescale_estimator': ([[]], 'estimating'),
    # acquiring at first (the input is no light it could find), or the bare aligner
    'alignment': ([[], ['-p', 'pat.enabled:=false']], 'aligning with'),
    # active (autostart: polling at 200 Hz) or unconfigured (waiting for a manager)
    'power_meter_driver': ([SIM_METER + ['-p', 'rate:=200.0'],
                            SIM_METER + ['-p', 'autostart:=false']], 'driver of'),
    'power_meter_simulator': ([['-p', 'rate:=200.0', '-p', 'wait_for_subscribers:=0']],
                              'simulat'),
    'led_link_simulator': ([['-p', 'wait_for_subscribers:=0']], 'simulat'),
}


@dataclass
class Run:
    """One signal to one node process, and how it ended."""

    node: str
    sig: str
    when: str                   # 'starting' or 'running'
    seconds: Optional[float]    # from the signal to the exit; None: a hang
    status: Optional[int]
    output: str = ''
    stacks: str = ''


@dataclass
class Storm:
    """Every run of a storm."""

    runs: list = field(default_factory=list)

    @property
    def hangs(self) -> list:
        """Return the runs whose node outlived BOUND."""
        return [r for r in self.runs if r.seconds is None]


def command(node: str, rng: random.Random) -> list:
    """Return the command line of a node of NODES, its arguments drawn."""
    args = rng.choice(NODES[node][0])
    return [sys.executable, '-c', f'from tskf_ros.tools.console import {node}; {node}()',
            '--ros-args', '-p', 'status_period:=0.0', *args]


def stacks(pid: int) -> str:
    """Return every thread's stack of a hung process (gdb), or why there are none."""
    gdb = shutil.which('gdb')
    if gdb is None:
        return '(no gdb)'
    done = subprocess.run([gdb, '-p', str(pid), '-batch', '-ex', 'thread apply all bt 30'],
                          capture_output=True, text=True, timeout=120)
    return done.stdout[-20000:]


def one(node: str, rng: random.Random, workdir: Path) -> Run:
    """Start the node, signal it at a random moment, wait for its end."""
    sig = rng.choice([signal.SIGINT, signal.SIGTERM])
    running = rng.random() < 0.5
    log = tempfile.TemporaryFile('w+', dir=workdir)
    proc = subprocess.Popen(command(node, rng), cwd=REPO, env=dict(os.environ), stdout=log,
                            stderr=subprocess.STDOUT, text=True)
    marker = NODES[node][1]
    deadline = time.monotonic() + START_TIMEOUT
    if running:     # once it says it runs, up to 0.5 s later
        while proc.poll() is None and time.monotonic() < deadline:
            log.seek(0)
            if marker in log.read():
                break
            time.sleep(0.05)
        delay = rng.uniform(0.0, 0.5)
    else:           # in its start: imports, rclpy.init, the node's construction
        delay = rng.uniform(0.0, 2.0)
    time.sleep(delay)
    sent = time.monotonic()
    proc.send_signal(sig)
    try:
        status = proc.wait(timeout=BOUND)
        seconds: Optional[float] = time.monotonic() - sent
        trace = ''
    except subprocess.TimeoutExpired:
        seconds, trace = None, stacks(proc.pid)
        proc.kill()
        status = proc.wait()
    log.seek(0)
    return Run(node, sig.name, 'running' if running else 'starting', seconds, status,
               log.read(), trace)


def publish_input(stop: threading.Event) -> None:
    """Publish Illuminance on `measurement` and `intensity` at about RATE Hz until stop."""
    import rclpy
    from rclpy.context import Context
    from sensor_msgs.msg import Illuminance

    from tskf_ros.messages import conversions
    from tskf_ros.messages.qos import SENSOR_OUTPUT_QOS
    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('shutdown_storm_input', context=context)
    pubs = [node.create_publisher(Illuminance, topic, SENSOR_OUTPUT_QOS)
            for topic in ('measurement', 'intensity')]
    k = 0
    try:
        while not stop.is_set():
            k += 1
            msg = conversions.power_to_msg(1_000_000_000 + k * int(1e9 / RATE), 1.0)
            for pub in pubs:
                pub.publish(msg)
            time.sleep(1.0 / RATE)      # pacing the stream, not a synchronisation
    finally:
        node.destroy_node()
        context.try_shutdown()


def storm(nodes: list, signals: int, *, seed: int = 0, parallel: int = 3) -> Storm:
    """Send `signals` signals to each node (`parallel` processes at a time) under input."""
    # A child inherits an ignored SIGINT, and a node started so ignores a SIGINT until its
    # runner's handler is in place: it runs on.  This process's SIGINT is ignored when the
    # suite runs as a background job of a shell without job control (`.ci/run &`, nohup,
    # a CI runner's script: POSIX has the shell ignore SIGINT there, and Python keeps an
    # ignored SIGINT).  The children are started with Python's own handler in place here,
    # so theirs is SIG_DFL.
    restore = None
    if (threading.current_thread() is threading.main_thread()
            and signal.getsignal(signal.SIGINT) is signal.SIG_IGN):
        restore = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        return _storm(nodes, signals, seed, parallel)
    finally:
        if restore is not None:
            signal.signal(signal.SIGINT, restore)


def _storm(nodes: list, signals: int, seed: int, parallel: int) -> Storm:
    """Run storm() with this process's SIGINT as it is."""
    rng = random.Random(seed)
    jobs = [node for node in nodes for _ in range(signals)]
    rng.shuffle(jobs)
    out = Storm()
    lock = threading.Lock()
    stop = threading.Event()
    feeder = threading.Thread(target=publish_input, args=(stop,), daemon=True)
    feeder.start()
    with tempfile.TemporaryDirectory() as tmp:
        def worker(seed: int) -> None:
            r = random.Random(seed)
            while True:
                with lock:
                    if not jobs:
                        return
                    node = jobs.pop()
                run = one(node, r, Path(tmp))
                with lock:
                    out.runs.append(run)
        threads = [threading.Thread(target=worker, args=(seed * 100 + i,))
                   for i in range(parallel)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    stop.set()
    feeder.join(timeout=10)
    return out


def main() -> None:
    """Run a storm from the command line: NODE[,NODE...] SIGNALS."""
    nodes = sys.argv[1].split(',') if len(sys.argv) > 1 else list(NODES)
    signals = int(sys.argv[2]) if len(sys.argv) > 2 else 10
    t0 = time.monotonic()
    s = storm(nodes, signals)
    for node in nodes:
        runs = [r for r in s.runs if r.node == node]
        ended = sorted(r.seconds for r in runs if r.seconds is not None)
        print(f'{node}: {len(runs)} signals, {len(runs) - len(ended)} hangs, end after the '
              f'signal: median {ended[len(ended) // 2]:.2f} s, max {ended[-1]:.2f} s; '
              f'statuses {sorted({r.status for r in runs})}' if ended else f'{node}: all hung')
    for r in s.hangs:
        print(f'--- hang: {r.node} {r.sig} {r.when}\n{r.output[-3000:]}\n{r.stacks}')
    print(f'{time.monotonic() - t0:.0f} s in all')


if __name__ == '__main__':
    main()
