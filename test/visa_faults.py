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
The simulated PM100 bench of the power-meter tests, and what pyvisa-sim cannot simulate.

`bench(tmp_path)` copies config/pm100_sim.yaml into tmp_path, so that each test gets a
device of its own (pyvisa-sim keeps one set of devices per definitions file and process),
and returns a Bench: the backend string, and a second session on the simulated meter
through which the test plays the light on the sensor and the meter's front panel
(SIM:POW <text>, SENS:POW:UNIT <unit>) and reads back what the driver set.

`FaultyOpener` wraps the real pyvisa-sim opener with the faults of a real bench that
pyvisa-sim has no way to produce: the device absent (open fails as a missing USB device
does), a read query that times out once, the cable pulled (every I/O on an open resource
fails with VI_ERROR_CONN_LOST, and opening fails) and plugged back.

`run_hanging_driver(command)` is the main of a driver process whose meter blocks on one
query until its timeout (a USB read that hangs): it prints HANG_MARK when the query
starts, for a test that interrupts it there.
"""

from dataclasses import dataclass
from functools import partial
from pathlib import Path
import shutil
import sys
import time

import pyvisa
from pyvisa.constants import StatusCode

from tskf_ros.owc.meter_settings import DEFAULT_RESOURCE
from tskf_ros.owc.power_meter import VisaOpener

SIM_YAML = Path(__file__).resolve().parent.parent / 'config' / 'pm100_sim.yaml'


@dataclass
class Bench:
    """A simulated PM100 and a session on it that plays the world around the driver."""

    backend: str
    session: object

    def set_power(self, text: str) -> None:
        """Make MEAS:POW? answer `text` from now on."""
        self.session.write(f'SIM:POW {text}')

    def set_unit(self, unit: str) -> None:
        """Switch the meter's unit (what its front panel would do)."""
        self.session.write(f'SENS:POW:UNIT {unit}')

    def query(self, command: str) -> str:
        """Ask the simulated meter directly."""
        return self.session.query(command).strip()


def bench(tmp_path: Path) -> Bench:
    """Return a Bench on a fresh copy of config/pm100_sim.yaml."""
    path = tmp_path / 'pm100_sim.yaml'
    shutil.copy(SIM_YAML, path)
    backend = f'{path}@sim'
    session = pyvisa.ResourceManager(backend).open_resource(
        DEFAULT_RESOURCE, read_termination='\n', write_termination='\n', timeout=1000)
    return Bench(backend, session)


class FaultyResource:
    """A pyvisa-sim resource that fails when its opener says so."""

    def __init__(self, opener: 'FaultyOpener', inner) -> None:
        self.opener, self.inner = opener, inner
        self.clears = 0
        self.closed = False

    def _check(self) -> None:
        if not self.opener.present:
            raise pyvisa.errors.VisaIOError(StatusCode.error_connection_lost)

    def write(self, message: str) -> object:
        """Write, unless the cable is out."""
        self._check()
        return self.inner.write(message)

    def query(self, message: str) -> str:
        """Query, unless the cable is out or a timeout is due on this command."""
        self._check()
        if message == self.opener.timeout_command and self.opener.timeouts > 0:
            self.opener.timeouts -= 1
            raise pyvisa.errors.VisaIOError(StatusCode.error_timeout)
        return self.inner.query(message)

    def clear(self) -> None:
        """Count the device clears: pyvisa-sim has none."""
        self._check()
        self.clears += 1

    def close(self) -> None:
        """Close the simulated session."""
        self.closed = True
        self.inner.close()


class FaultyOpener:
    """Open pyvisa-sim resources, or fail as a real bench does."""

    def __init__(self, backend: str, *, present: bool = True) -> None:
        self.backend = backend
        self.inner = VisaOpener(backend)
        self.present = present
        self.timeouts = 0                   # the next n queries of timeout_command time out
        self.timeout_command = 'MEAS:POW?'
        self.attempts = 0
        self.resources: list = []
        self.closed = False

    def open_resource(self, resource: str, timeout_ms: int) -> FaultyResource:
        """Open through pyvisa-sim if the device is present; else fail as pyvisa-py does."""
        self.attempts += 1
        if not self.present:
            raise ValueError('No device found.')
        if self.closed:                     # configured again after a cleanup
            self.inner, self.closed = VisaOpener(self.backend), False
        self.resources.append(FaultyResource(self, self.inner.open_resource(resource,
                                                                            timeout_ms)))
        return self.resources[-1]

    def unplug(self) -> None:
        """Pull the cable: open resources fail, and opening does."""
        self.present = False

    def plug(self) -> None:
        """Plug the cable back in."""
        self.present = True

    def close(self) -> None:
        """Close the backend."""
        self.closed = True
        self.inner.close()


HANG_MARK = 'the query hangs now'
# the answers of the hanging meter to what it does not hang on
ANSWERS = {'*IDN?': 'Fake,Hanging,0,0', 'SENS:POW:UNIT?': 'W', 'SYST:ERR?': '0,"No error"',
           'MEAS:POW?': '1.0E-03'}


class HangingResource:
    """A meter that answers, but blocks on one query until its timeout (a USB read)."""

    def __init__(self, hang_on: str, timeout_ms: int) -> None:
        self.hang_on, self.timeout_s = hang_on, timeout_ms / 1000

    def write(self, message: str) -> int:
        """Take any command."""
        return len(message)

    def query(self, message: str) -> str:
        """Answer from ANSWERS; on hang_on, print HANG_MARK and time out (VI_ERROR_TMO)."""
        if message != self.hang_on:
            return ANSWERS[message]
        print(HANG_MARK, flush=True)
        deadline = time.monotonic() + self.timeout_s
        while time.monotonic() < deadline:
            time.sleep(0.01)
        raise pyvisa.errors.VisaIOError(StatusCode.error_timeout)

    def clear(self) -> None:
        """Do nothing: the device does not answer."""

    def close(self) -> None:
        """Do nothing: there is nothing to release."""


class HangingOpener:
    """Open HangingResources."""

    def __init__(self, hang_on: str) -> None:
        self.hang_on = hang_on

    def open_resource(self, resource: str, timeout_ms: int) -> HangingResource:
        """Return a new hanging meter."""
        return HangingResource(self.hang_on, timeout_ms)

    def close(self) -> None:
        """Do nothing: there is no backend."""


def run_hanging_driver(hang_on: str) -> None:
    """Run power_meter_driver (sys.argv: its arguments) on a meter that hangs on hang_on."""
    from tskf_ros.nodes.node_runner import run_node
    from tskf_ros.nodes.power_meter_driver import DESCRIPTION, NODE_NAME, PowerMeterDriver
    from tskf_ros.owc.meter_settings import MeterError
    run_node(partial(PowerMeterDriver, opener=HangingOpener(hang_on)), name=NODE_NAME,
             description=DESCRIPTION, startup_errors=(MeterError,), args=sys.argv)
