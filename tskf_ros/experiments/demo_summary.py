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

"""The live demo's figures: its estimates against the truth at their stamps."""

from dataclasses import dataclass

import numpy as np

from tskf_ros.core.linear_models import OWC_LINEAR_RANGE
from tskf_ros.core.time_scales import jumps
from tskf_ros.core.units import NS


@dataclass
class Summary:
    """The demo's figures."""

    samples: int
    published: int
    predicted: int
    corrected: int
    gaps: list            # (point after the gap s, J s)
    rms_predicted: float
    rms_corrected: float
    rms_predicted_linear: float
    rms_corrected_linear: float
    worst: list           # (t s, J before t or 0, truth, predicted, corrected)


def _by_stamp(store: dict) -> dict:
    return {k: (v[0] if isinstance(v, tuple) else v) for k, v in store.items()}


def summarise(record, *, period: float = 1.0) -> Summary:
    """Compare the estimates with the truth at the estimates' stamps (a demo Record)."""
    truth = _by_stamp(record.truth)
    pred, corr = _by_stamp(record.predicted), _by_stamp(record.corrected)
    stamps = sorted(record.power)
    t_s = np.array(stamps, dtype=float) / NS
    gaps = jumps(t_s, period=period) if t_s.size >= 2 else []
    jump_at = {round(t * NS): J for t, J in gaps}
    common = [k for k in sorted(pred) if k in truth and k in corr]

    def rms(est: dict, keys: list) -> float:
        e = np.array([est[k] - truth[k] for k in keys])
        return float(np.sqrt(np.mean(e ** 2))) if e.size else float('nan')

    lo, hi = OWC_LINEAR_RANGE
    linear = [k for k in common if lo <= truth[k] <= hi]
    worst = sorted(common, key=lambda k: -abs(pred[k] - truth[k]))[:5]
    return Summary(
        samples=len(truth), published=len(stamps), predicted=len(pred), corrected=len(corr),
        gaps=gaps, rms_predicted=rms(pred, common), rms_corrected=rms(corr, common),
        rms_predicted_linear=rms(pred, linear), rms_corrected_linear=rms(corr, linear),
        worst=[(k / NS, jump_at.get(k, 0.0), truth[k], pred[k], corr[k]) for k in worst])


def format_summary(s: Summary) -> str:
    """Format the summary as the demo prints it."""
    lines = [
        f'messages: {s.samples} true angles, {s.published} received-power samples '
        f'({s.samples - s.published} gaps or drops), {s.predicted} predicted and '
        f'{s.corrected} corrected estimates',
        f'gaps (J > 1.5 s): {len(s.gaps)}' + (': ' + ', '.join(
            f'J = {J:g} s before t = {t:g}' for t, J in s.gaps) if s.gaps else ''),
        f'RMS error vs true angle (rad): predictor {s.rms_predicted:.4f}, '
        f'corrected {s.rms_corrected:.4f}',
        f'  where theta is in the linear range of eq. (2): predictor '
        f'{s.rms_predicted_linear:.4f}, corrected {s.rms_corrected_linear:.4f}',
        'five worst points (predictor error):',
        '  t (s)     J before   theta    predicted  corrected',
    ]
    for t, J, th, p, c in s.worst:
        lines.append(f'  {t:8.2f}  {J:8g}  {th:8.4f}  {p:9.4f}  {c:9.4f}')
    return '\n'.join(lines)
