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

"""The alignment Monte Carlo's command line: its defaults are the paper's settings."""

import pytest

from tskf_ros.experiments import alignment_mc_arguments as cli


def test_defaults_are_the_papers_settings():
    a = cli.parser().parse_args([])
    assert a.axes == 1 and a.runs == 1000 and a.beta == 1.2 and a.x2_0 == 5.0
    assert list(a.noise_levels) == pytest.approx([0.25 * k for k in range(11)], abs=1e-12)
    # Table I: R_sys = 0.04 V^2, so the single runs' noise is 0.2 V
    assert a.run_noise == pytest.approx(0.2, rel=1e-12)
    # Fig. 14's disturbance for the dropout sweep; the failing run of Fig. 9
    assert (a.dropout_beta, a.fig9_beta) == (2.8, 16.0)
    assert a.dropout_levels == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]


@pytest.mark.parametrize('argv', [['--runs', '0'], ['--beta', 'nan'], ['--x2-0', 'inf'],
                                  ['--dropout-levels', '1.5'],
                                  ['--units-per-degree', '2', '--literal-units']])
def test_bad_values_are_refused_in_one_line(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.parser().parse_args(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith('python -m tskf_ros.experiments.alignment_mc: error:')
