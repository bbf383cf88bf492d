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

"""The time-scale filter's covariance around a jump of J s (Cai et al. (3), B&W Ex. 3.20)."""

import argparse
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from tskf_ros.core import linear_models as models
from tskf_ros.core.irregular import jump_covariance, JumpCovariance, steady_covariance
from tskf_ros.core.timescale_kalman import TRANSITIONS
from tskf_ros.experiments.output import save_results

PERIOD = 1.0                            # s, the discrete parts of Cai's T_d
J_GRID = np.linspace(1.0, 6.0, 26)      # s
J_TABLE = (1.0, 2.0, 3.0, 4.0, 5.0, 6.0)
DEFINITION = '\n'.join((
    'Points every h = 1 s, filter in its steady state (grey),',
    'then one jump: the next point after t* is t* + J.',
    '',
    'peak      = predicted covariance at t* + J, before its',
    '            measurement (Table 3 weighs y(t*) by R / J)',
    'corrected = covariance of the estimate at t* + J after',
    '            its measurement (R / h)',
    '',
    'tskf_ros.core.irregular.jump_covariance(model, J, period=h)'))


def table(model: models.LinearModel, jumps: Sequence[float] = J_TABLE, *,
          period: float = PERIOD) -> dict:
    """{transition: [row per J]} with the diagonals of the covariances and the recovery."""
    out = {}
    for transition in TRANSITIONS:
        rows = []
        for J in jumps:
            r = jump_covariance(model, J, period=period, transition=transition)
            rows.append({'J': J, 'peak_variances': np.diag(r.P_peak),
                         'after_variances': np.diag(r.P_after),
                         'steady_variances': np.diag(r.P_steady),
                         'recovery_steps': r.recovery_steps, 'regressive': r.regressive})
        out[transition] = rows
    return out


def curves(model: models.LinearModel, transition: str, grid: np.ndarray = J_GRID, *,
           period: float = PERIOD) -> list[JumpCovariance]:
    """jump_covariance over a grid of J."""
    P_ss = steady_covariance(model, period, transition=transition)
    return [jump_covariance(model, J, period=period, transition=transition, P_steady=P_ss)
            for J in grid]


def plot(model_list: Sequence[models.LinearModel], grid: np.ndarray = J_GRID):
    """One column per model, one row per state: peak and corrected variance against J."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    rows = max(len(m.state_names) or m.A.shape[0] for m in model_list)
    fig, ax = plt.subplots(rows, len(model_list), figsize=(6 * len(model_list), 3.6 * rows),
                           squeeze=False)
    styles = {'euler': '-', 'exact': '--'}
    for col, m in enumerate(model_list):
        for transition in TRANSITIONS:
            res = curves(m, transition, grid)
            ls = styles[transition]
            for i in range(m.A.shape[0]):
                a = ax[i, col]
                peak = np.array([r.P_peak[i, i] for r in res])
                after = np.array([r.P_after[i, i] for r in res])
                a.semilogy(grid, peak, 'C3' + ls, label=f'peak P(t*+J), {transition}')
                a.semilogy(grid, after, 'C0' + ls, label=f'corrected P(t*+J|t*+J), {transition}')
                a.axhline(res[0].P_steady[i, i], color='0.5', ls=ls, lw=0.8,
                          label=f'steady (J = h), {transition}')
                bad = [r.J for r in res if not r.regressive]
                for J in bad:
                    a.axvline(J, color='k', lw=0.5, ls=':')
        for i in range(m.A.shape[0]):
            a = ax[i, col]
            name = m.state_names[i] if i < len(m.state_names) else f'x{i + 1}'
            a.set_title(f'{m.name}: variance of {name}')
            a.set_xlabel('jump length J (s), nominal period h = 1 s')
            a.grid(True, which='both', alpha=0.3)
            a.legend(fontsize=7, loc='best')
        for i in range(m.A.shape[0], rows):
            ax[i, col].axis('off')
            ax[i, col].text(0.0, 0.5, DEFINITION, fontsize=8, va='center', family='monospace')
    fig.suptitle('Time-scale filter around one jump: solid = I + mu A (B&W Table 3), '
                 'dashed = exact sampled plant; dotted = I + J A singular')
    fig.tight_layout()
    return fig


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Print the table at J = 1..6, write jump_covariance.png and jump_covariance.json."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--out', type=Path, required=True, help='output directory')
    args = parser.parse_args(argv)
    model_list = [models.owc(), models.spring_mass()]
    data = {'period': PERIOD, 'definition': 'tskf_ros.core.irregular.jump_covariance'}
    for m in model_list:
        data[m.name] = table(m)
        for transition, rows in data[m.name].items():
            print(f'{m.name} ({transition}), steady {_fmt(rows[0]["steady_variances"])}')
            for r in rows:
                flag = '' if r['regressive'] else '  (I + J A singular)'
                print(f'  J = {r["J"]:.0f}: peak {_fmt(r["peak_variances"])}, corrected '
                      f'{_fmt(r["after_variances"])}, recovery {r["recovery_steps"]} steps{flag}')
    save_results(args.out, 'jump_covariance', plot(model_list), data)
    return 0


def _fmt(v: np.ndarray) -> str:
    return '[' + ', '.join(f'{x:.6g}' for x in v) + ']'


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(main)
