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

"""The command line of the LED alignment Monte Carlo (tskf_ros.experiments.alignment_mc)."""

import argparse
import math
from pathlib import Path

from tskf_ros import led
from tskf_ros.experiments import alignment_pat, arguments

DESCRIPTION = ('Monte Carlo comparison of LED alignment algorithms '
               '(Solanki et al. 2018, Fig. 8-10).')
DEFAULT_NOISE_LEVELS = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0, 2.25, 2.5)
DEFAULT_DROPOUTS = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5)
FAIL_BETA = 16.0        # deg/s: the EKF loses every run at 50 ms steps (8 deg/s still tracks)
DROPOUT_BETA = 2.8      # deg/s: the disturbance of the paper's experiments (Fig. 14)
# the supervised algorithms (acquire, track, detect loss, re-acquire): alignment_pat
PAT_ALGORITHMS = tuple(alignment_pat.PAT_ALGORITHMS)


def parser() -> argparse.ArgumentParser:
    """Build the command-line interface."""
    p = argparse.ArgumentParser(prog='python -m tskf_ros.experiments.alignment_mc',
                                description=DESCRIPTION)
    p.add_argument('--axes', type=int, choices=(1, 2), default=1,
                   help='1: a receiver turned about one axis (this page of options); 2: a '
                        'pan-tilt receiver (see --axes 2 --help)')
    arguments.add_runs(p, 1000, 'noise level')
    arguments.add_noise_levels(p, DEFAULT_NOISE_LEVELS)
    p.add_argument('--beta', type=arguments.rate_deg_s,
                   default=1.2, help='disturbance rate, deg/s (1.2)')
    arguments.add_run_options(p, dt=led.PAPER_DT)
    arguments.add_scheduler(p)
    p.add_argument('--dropout', type=float, default=0.0,
                   help='probability that a measurement is missing (0)')
    p.add_argument('--x2-0', type=arguments.angle_deg,
                   default=5.0, help='initial scan mean, deg (5)')
    p.add_argument('--cold-start', type=float, default=0.0, metavar='DEG',
                   help='initial angle uniform on +-DEG (x2_0 = 0; the supervised algorithms '
                        'then start with a search); 0: the known start of the paper (--x2-0)')
    p.add_argument('--blocked', type=arguments.numbers(0.0, 1e6), default=[],
                   metavar='START,STOP',
                   help='no light in every run from START to STOP s (a blocked beam: the '
                        "supervisor's loss and re-acquisition); default: never")
    p.add_argument('--algorithms', type=lambda t: [a for a in t.split(',') if a], default=None,
                   help='comma list of the algorithms compared (default: '
                        + ','.join(led.ALGORITHMS + PAT_ALGORITHMS) + '; lqg: the plain ones)')
    units = p.add_mutually_exclusive_group()
    units.add_argument('--units-per-degree',
                       type=arguments.number(0.0, 1e6, open_low=True), default=None,
                       help='fit units per degree of g (default: the 20%%-at-15-deg unit)')
    units.add_argument('--literal-units', action='store_true',
                       help='read g with phi in degrees, as printed (1 unit per degree)')
    p.add_argument('--controller', choices=led.CONTROLLERS, default='p',
                   help="the EKF's controller: p (the paper's eq. (21)) or lqg "
                        '(tskf_ros.led.lqg_alignment)')
    p.add_argument('--x1-floor',
                   type=arguments.number(-arguments.MAX_NOISE, arguments.MAX_NOISE), default=None,
                   help='keep x1hat >= this (not in the paper; default off)')
    p.add_argument('--clip-three-point', action='store_true',
                   help='clip gamma_p of eq. (26) to [-gamma, gamma] (not in the paper)')
    p.add_argument('--json', type=Path, help='write the comparison as JSON')
    p.add_argument('--png', type=Path, help='write the comparison figure (Fig. 10)')
    p.add_argument('--acquisition-png', type=Path,
                   help="write the comparison's acquisition-time histograms (first noise level)")
    p.add_argument('--no-comparison', action='store_true', help='skip the noise-level sweep')
    p.add_argument('--fig8', type=Path, help='write the beta = --beta tracking run (Fig. 8)')
    p.add_argument('--fig9', type=Path, help='write the failing run (Fig. 9)')
    p.add_argument('--pat-run', type=Path, help='write one ekf_pat run (--run-noise, '
                   '--cold-start, blocked from 8 to 11 s): angle, state and intensity in time')
    p.add_argument('--fig9-beta', type=arguments.rate_deg_s, default=FAIL_BETA,
                   help=f'beta of the failing run, deg/s ({FAIL_BETA:g})')
    p.add_argument('--run-noise', type=arguments.noise_volts,
                   default=math.sqrt(led.PAPER_R_SYS[0][0]),
                   help='noise of the Fig. 8/9 runs, V (0.2: Table I R_sys)')
    p.add_argument('--dropout-png', type=Path, help='write tracking vs dropout probability')
    p.add_argument('--dropout-json', type=Path, help='write the dropout sweep as JSON')
    p.add_argument('--dropout-levels', type=arguments.numbers(0.0, 1.0),
                   default=list(DEFAULT_DROPOUTS))
    p.add_argument('--dropout-noise', type=arguments.noise_volts, default=1.0,
                   help='noise level of the dropout sweep, V (1.0)')
    p.add_argument('--dropout-beta', type=arguments.rate_deg_s, default=DROPOUT_BETA,
                   help=f'beta of the dropout sweep, deg/s ({DROPOUT_BETA:g}, as in Fig. 14)')
    return p
