#!/usr/bin/env python3
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
Run the DDS, subprocess and recorder tests N times in a row under CPU load; count passes.

    .venv/bin/python bench/flakiness.py                 # 20 runs, two busy loops per core
    .venv/bin/python bench/flakiness.py -n 5 --no-load
    .venv/bin/python bench/flakiness.py -n 3 test/bag/test_recorder.py
    .venv/bin/python bench/flakiness.py -n 100 --named  # the tests that once flaked

Not part of the test suite (nor of CI): it proves that the tests which wait on DDS,
subprocesses or the recorder do not flake on a loaded machine.  One busy-loop process per
core (started here, killed here, by pid) keeps every core busy; each pytest run gets its
own ROS_DOMAIN_ID, taken in turn from --domains, so that a run never hears a previous one.
Two busy loops per core by default (load about twice the cores, as a shared machine gives).
Each run's line gives the 1-minute load average after it.  At the end it prints how many
runs passed and, for the failures, the test ids and how often each failed.  Exit status 0
when every run passed.  --named runs the tests that once failed under load (NAMED).
"""

import argparse
import collections
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ElementTree

REPO = Path(__file__).resolve().parent.parent
# every test file that talks DDS, starts processes or records
TESTS = ('test/nodes/test_timescale_estimator_process.py', 'test/bag/replay/test_adapters.py',
         'test/bag/test_recorder.py', 'test/nodes/test_alignment.py',
         'test/nodes/test_timescale_estimator.py', 'test/bag/replay/test_cli.py',
         'test/package/test_ros_env.py', 'test/package/test_colcon_build.py')
# tests that once failed on a loaded machine: --named runs these
NAMED = ('test/tools/test_console.py::test_ctrl_c_while_the_modules_load_is_quiet'
         '[timescale_estimator]',
         'test/nodes/test_power_meter_driver_lifecycle.py')
# s: one pytest run that takes longer than this is killed and counted as failed (a hang)
RUN_LIMIT = 900.0
BUSY = 'while True:\n    pass\n'


def domains(spec):
    """Parse '40-49' or '40,41,45' into a list of ROS domain ids."""
    out = []
    for part in spec.split(','):
        lo, _, hi = part.partition('-')
        out.extend(range(int(lo), int(hi or lo) + 1))
    if not out or not all(0 <= d <= 232 for d in out):
        raise argparse.ArgumentTypeError(f'bad domain ids {spec!r}')
    return out


def start_load(cores):
    """Start one busy-loop process per core; return them."""
    return [subprocess.Popen([sys.executable, '-c', BUSY], stdin=subprocess.DEVNULL,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            for _ in range(cores)]


def stop_load(procs):
    """Kill the busy loops (only those, by their own handles) and reap them."""
    for p in procs:
        if p.poll() is None:
            p.kill()
    for p in procs:
        p.wait(timeout=30)


def failed_ids(junit):
    """Return the ids (file::name) of the failed or errored test cases of a JUnit XML file."""
    try:
        root = ElementTree.parse(junit).getroot()
    except (OSError, ElementTree.ParseError):
        return []
    out = []
    for case in root.iter('testcase'):
        if case.find('failure') is not None or case.find('error') is not None:
            path = case.get('classname', '').replace('.', '/')
            out.append(f'{path}.py::{case.get("name")}')
    return out


def run_once(index, domain, tests, extra, workdir):
    """Run pytest once in its own domain; return (passed, failed test ids, seconds, tail)."""
    junit = Path(workdir) / f'run{index}.xml'
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    cmd = [sys.executable, '-m', 'pytest', '-q', '-p', 'no:cacheprovider',
           f'--junitxml={junit}', *extra, *tests]
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=RUN_LIMIT)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, 9)              # the run's own session: pytest and its children
        out, _ = proc.communicate()
        return False, [f'(run killed after {RUN_LIMIT:g} s: a hang)'], \
            time.monotonic() - t0, out[-2000:]
    elapsed = time.monotonic() - t0
    ids = failed_ids(junit)
    if proc.returncode != 0 and not ids:
        ids = [f'(pytest exit status {proc.returncode})']
    return proc.returncode == 0, ids, elapsed, out[-2000:]


def main(argv=None):
    """Run the tests N times under load; print the tally; return 0 if all passed."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('tests', nargs='*', default=list(TESTS),
                        help='test files or ids (default: the DDS, subprocess and recorder '
                        'tests)')
    parser.add_argument('-n', '--runs', type=int, default=20, help='runs (default 20)')
    parser.add_argument('--no-load', dest='load', action='store_false',
                        help='no busy loops')
    parser.add_argument('--named', action='store_true',
                        help='run the tests that once failed under load (instead of tests)')
    parser.add_argument('--cores', type=int, default=2 * (os.cpu_count() or 1),
                        help='busy loops to start (default: two per core)')
    parser.add_argument('--domains', type=domains, default=domains('40-49'),
                        help='ROS domain ids to use in turn (default 40-49)')
    parser.add_argument('--pytest-args', default='', help='extra pytest arguments, one string')
    opts = parser.parse_args(argv)
    extra = opts.pytest_args.split()
    if opts.named:
        opts.tests = list(NAMED)
    load = start_load(opts.cores) if opts.load else []
    print(f'{opts.runs} runs of {" ".join(opts.tests)}; '
          f'{len(load)} busy loop(s) on {os.cpu_count()} core(s)', flush=True)
    passed, failures, times = 0, collections.Counter(), []
    try:
        with tempfile.TemporaryDirectory(prefix='flakiness-') as workdir:
            for i in range(opts.runs):
                domain = opts.domains[i % len(opts.domains)]
                ok, ids, elapsed, tail = run_once(i, domain, opts.tests, extra, workdir)
                times.append(elapsed)
                passed += ok
                failures.update(ids)
                print(f'run {i + 1:2d}/{opts.runs} (domain {domain}): '
                      f'{"passed" if ok else "FAILED"} in {elapsed:.0f} s, load '
                      f'{os.getloadavg()[0]:.1f}'
                      + ('' if ok else ': ' + ', '.join(ids)), flush=True)
                if not ok:
                    print('    ' + tail.replace('\n', '\n    '), flush=True)
    finally:
        stop_load(load)
    where = f'{len(load)} busy loops' if load else "the machine's own load"
    print(f'\n{passed}/{opts.runs} runs passed under {where} (run time {min(times):.0f}-'
          f'{max(times):.0f} s)' if times else 'no runs')
    for test_id, count in failures.most_common():
        print(f'  {count}x {test_id}')
    return 0 if passed == opts.runs else 1


if __name__ == '__main__':
    sys.exit(main())
