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
Benchmark: one power-meter reading against the simulated PM100, with and without unit checks.

    python bench/bench_power_meter.py [--readings 2000]

PowerMeter.poll() on config/pm100_sim.yaml (pyvisa-sim, no USB): the cost the driver adds
per reading, side by side for unit_check_every = 1 (SENS:POW:UNIT? before every MEAS:POW?,
the default), 10 and 0 (never), and the query latency the driver stamps with (its midpoint).
On a real PM100 over USBTMC the round trips dominate instead (about 1 to 3 ms each, plus
about 3 ms per averaged sample): the ratio of queries per reading (2 vs 1.1 vs 1) is then
the cost of the unit check.
"""

import argparse
from pathlib import Path
import platform
import shutil
import sys
import tempfile
import time

# runnable from a source checkout without installing: the repository root on the path
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tskf_ros.owc.meter_settings import MeterConfig  # noqa: E402
from tskf_ros.owc.power_meter import PowerMeter  # noqa: E402

SIM_YAML = Path(__file__).resolve().parent.parent / 'config' / 'pm100_sim.yaml'


def run(backend: str, every: int, n: int) -> tuple[float, float]:
    """Return (s per published reading, mean query latency s) over n readings."""
    m = PowerMeter(MeterConfig(backend=backend, unit_check_every=every))
    m.poll()
    assert m.connected, m.last_error
    t0 = time.perf_counter()
    for _ in range(n):
        m.poll()
    elapsed = time.perf_counter() - t0
    assert m.published == n, m.skipped
    lat = m.diagnostics()[2]['latency_mean_ms'] / 1e3
    m.close()
    return elapsed / n, lat


def main() -> None:
    """Print the per-reading cost of each unit-check setting side by side."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--readings', type=int, default=2000)
    args = parser.parse_args()
    print(f'{platform.python_implementation()} {platform.python_version()}, '
          f'{platform.machine()}, {args.readings} readings each')
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for every in (1, 10, 0):
            # a fresh definitions file per run: pyvisa-sim keeps one device per file
            path = Path(tmp) / f'pm100_{every}.yaml'
            shutil.copy(SIM_YAML, path)
            rows.append((every, *run(f'{path}@sim', every, args.readings)))
    base = rows[-1][1]
    print(f'{"unit_check_every":>16} {"us/reading":>11} {"query latency us":>17} '
          f'{"ratio to 0":>11}')
    for every, per, lat in rows:
        print(f'{every:>16} {per * 1e6:>11.1f} {lat * 1e6:>17.1f} {per / base:>11.2f}')


if __name__ == '__main__':
    main()
