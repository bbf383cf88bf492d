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

"""The diagnostic tasks the nodes publish on /diagnostics, declared: levels and keys."""

from tskf_ros.core.diagnostic_status import INPUT_FREQUENCY, TIME_SCALE, TIMESTAMP_DELAY
from tskf_ros.led.alignment_diagnostics import ALIGNER, POINTING
from tskf_ros.led.alignment_session import (MISSING_REASONS,
                                            REJECT_REASONS as ALIGN_REJECT_REASONS,
                                            RESET_REASONS as ALIGN_RESET_REASONS)
from tskf_ros.messages.interface_spec import DiagnosticTask, KeyRow, LevelRow
from tskf_ros.messages.names import OUTPUT_FREQUENCY, POWER_METER
from tskf_ros.owc.meter_settings import SKIP_REASONS
from tskf_ros.owc.session.diagnostics import FILTER_HEALTH
from tskf_ros.owc.session.outcome import REJECT_REASONS, RESET_REASONS

__all__ = ['ALIGNER_TASK', 'ALIGNMENT_TIME_SCALE_TASK', 'ESTIMATOR_TIME_SCALE_TASK',
           'FILTER_HEALTH_TASK', 'INPUT_FREQUENCY_TASK', 'OUTPUT_FREQUENCY',
           'POINTING_TASK', 'POWER_METER', 'POWER_METER_TASK', 'readings_frequency_task',
           'samples_frequency_task', 'TIMESTAMP_DELAY_TASK']


def _reasons(reasons: tuple[str, ...]) -> str:
    return ', '.join(reasons)


# diagnostic_updater's FrequencyStatus (tskf_ros/core/diagnostic_status.py); the summaries
# are set in this order, so the last that applies is the one shown
FREQUENCY_LEVELS = (
    LevelRow('ERROR', 'no event in the window (the stream went silent, or never came)',
             'No events recorded.'),
    LevelRow('WARN', 'below the minimum acceptable frequency', 'Frequency too low.'),
    LevelRow('WARN', 'above the maximum acceptable frequency', 'Frequency too high.'),
    LevelRow('OK', 'otherwise', 'Desired frequency met'))
FREQUENCY_KEYS = (
    KeyRow(('Events in window',), 'events in the window of the last `window_size` = 5 '
           'updates (`%d`)'),
    KeyRow(('Events since startup',), 'events since the node started (`%d`)'),
    KeyRow(('Duration of window (s)',), 'the window (`%f`)'),
    KeyRow(('Actual frequency (Hz)',), 'events / window (`%f`)'),
    KeyRow(('Target frequency (Hz)',), 'the target the summary names (`%f`; absent '
           'without a target)'),
    KeyRow(('Minimum acceptable frequency (Hz)',), 'target x (1 - tolerance)'),
    KeyRow(('Maximum acceptable frequency (Hz)',), 'target x (1 + tolerance)'))

INPUT_FREQUENCY_TASK = DiagnosticTask(
    INPUT_FREQUENCY, 'FrequencyStatus of the input messages, accepted or not, against '
    '`expected_rate` (0: 1 / `period`, 1 / `dt` for the alignment node) with '
    '`rate_tolerance`',
    FREQUENCY_LEVELS, FREQUENCY_KEYS)

# diagnostic_updater's TimeStampStatus: as FrequencyStatus, the last summary that applies
TIMESTAMP_DELAY_TASK = DiagnosticTask(
    TIMESTAMP_DELAY, 'TimeStampStatus: node clock at reception minus `header.stamp`, '
    'acceptable from -1 s to 5 s',
    (LevelRow('WARN', 'no stamped message since the last update',
              'No data since last update.'),
     LevelRow('ERROR', 'a delay below -1 s', 'Timestamps too far in future seen.'),
     LevelRow('ERROR', 'a delay above 5 s', 'Timestamps too far in past seen.'),
     LevelRow('ERROR', 'a message stamped 0', 'Zero timestamp seen.'),
     LevelRow('OK', 'otherwise', 'Timestamps are reasonable.')),
    (KeyRow(('Earliest timestamp delay:',), 'smallest delay since the last update (s, '
            '`%f`)'),
     KeyRow(('Latest timestamp delay:',), 'largest delay since the last update'),
     KeyRow(('Earliest acceptable timestamp delay:',), '-1'),
     KeyRow(('Latest acceptable timestamp delay:',), '5'),
     KeyRow(('Late diagnostic update count:',), 'updates that saw a delay above 5 s'),
     KeyRow(('Early diagnostic update count:',), 'updates that saw a delay below -1 s'),
     KeyRow(('Zero seen diagnostic update count:',), 'updates that saw a zero stamp')))

FILTER_HEALTH_TASK = DiagnosticTask(
    FILTER_HEALTH, 'the filter: samples, rejections and resets by reason',
    (LevelRow('ERROR', 'a step gave a non-finite or absurd state since the last update '
              '(`state_health`)', 'filter re-initialised itself: ...'),
     LevelRow('OK', 'otherwise, saying how many samples were rejected since the last '
              'update')),
    (KeyRow(('Samples received', 'Samples accepted', 'Samples inserted late'),
            'measurements received, accepted as points, inserted late (the filter re-run)'),
     KeyRow(('Messages lost (transport)',), "the middleware's count of measurements lost in "
            'transport'),
     KeyRow(('Inputs received', 'Inputs accepted', 'Input in force'),
            'inputs u on `input`, and the u held now'),
     KeyRow(('Points in history',), 'points kept for rewinding on a late sample'),
     KeyRow(('Covariance trace',), 'trace P of the newest predictor'),
     KeyRow(('Rejections', 'Resets'), 'totals of the two rows below'),
     KeyRow(('Rejected (<reason>)',), 'samples not used, by reason: '
            + _reasons(REJECT_REASONS)),
     KeyRow(('Resets (<reason>)',), 'filter re-initialisations, by reason: '
            + _reasons(RESET_REASONS))))

ESTIMATOR_TIME_SCALE_TASK = DiagnosticTask(
    TIME_SCALE, 'the time scale: gaps, graininess, sampling intervals',
    (LevelRow('WARN', 'a gap longer than `max_gap` ended since the last update, or a '
              'sampling interval seen breaks observability (Fang & de Callafon III)'),
     LevelRow('OK', 'otherwise')),
    (KeyRow(('Gaps',), 'intervals between measurement points longer than `jump_factor` x '
            '`period`'),
     KeyRow(('Longest gap J (s)', 'Last gaps J (s)'), 'the longest of the last 1000 gaps, '
            'the last 20'),
     KeyRow(('mu current (s)', 'mu max (s)'), 'the last and the largest graininess'),
     KeyRow(('Last stamp (s)', 'Transition'), 'the newest stamp, `euler` or `exact`'),
     KeyRow(('Intervals seen (periods)', 'Intervals seen (count)'),
            'the sampling intervals seen in nominal periods (at most 20 shown)'),
     KeyRow(('Interval warnings',), 'those that are pathological or degenerate for the '
            'model'),
     KeyRow(('Theorem 2 peak bound (low)', 'Theorem 2 peak bound (high)', 'Covariance'),
            "Fang & de Callafon's bounds of the peak covariance next to the filter's P "
            '(scalar models only)')))

ALIGNER_TASK = DiagnosticTask(
    ALIGNER, 'the aligner: samples, commands, missing and rejected samples, the EKF',
    (LevelRow('ERROR', 'the EKF state went beyond `state_limit` since the last update',
              'aligner restarted itself: ...'),
     LevelRow('WARN', 'the EKF has lost the transmitter (x1hat <= 0)'),
     LevelRow('WARN', "`axes` 2: a smoothing of the conical-scan EKF's window failed since "
              "the last update (a linear-algebra error; the filter's estimate was kept)",
              "N smoothing(s) of the filter's window failed since the last update: ..."),
     LevelRow('OK', 'otherwise; while `~/enable` is false the message says the loop is '
              'paused and how many samples came meanwhile: a paused loop is not a fault')),
    (KeyRow(('Algorithm', 'Paused'), 'the aligner, `yes` while `~/enable` is false'),
     KeyRow(('Samples received', 'Samples received while paused', 'Samples used'),
            'intensities received (paused or not), those received while paused, those '
            'used'),
     KeyRow(('Samples missed (stamps)',), 'samples the stamps say never came: round(mu) - 1 '
            'for each gap of mu `dt`, wherever they were lost (in transport, in a full '
            'subscription queue `queue_depth` under a burst, at the sensor)'),
     KeyRow(('Messages lost (transport)',), "the middleware's count of intensities lost in "
            'transport'),
     KeyRow(('Commands', 'Commands clamped', 'Base command (deg)'),
            'base commands sent, those limited by `max_step` or `base_limits`, the last'),
     KeyRow(('Missing (<reason>)',), 'samples treated as missing, by reason: '
            + _reasons(MISSING_REASONS)),
     KeyRow(('Rejected (<reason>)',), 'samples dropped, by reason: '
            + _reasons(ALIGN_REJECT_REASONS)),
     KeyRow(('Resets (<reason>)',), 'restarts, by reason: ' + _reasons(ALIGN_RESET_REASONS)),
     KeyRow(('x1 estimate (V)', 'x2 estimate (deg)', 'Covariance trace', 'Singular updates'),
            "the scanning EKF's estimate (the EKF only)"),
     KeyRow(('Tilt command (deg)', 'd_c estimate (deg)', 'd_e estimate (deg)'),
            "`axes` 2: the tilt joint's last command (`Base command (deg)` is the pan "
            "joint's), the conical-scan EKF's cross-elevation and elevation errors (with "
            '`x1 estimate (V)` and `Covariance trace`, while it steers)'),
     KeyRow(('Smoothing failures',), '`axes` 2: windows whose smoothing failed since the '
            'start, over restarts and reconfigurations (`pan_tilt.smooth_after`, '
            '`smooth_every`)')))

ALIGNMENT_TIME_SCALE_TASK = DiagnosticTask(
    TIME_SCALE, 'the time scale of the intensity stream: gaps and graininess',
    (LevelRow('WARN', 'a gap longer than `max_gap` ended since the last update'),
     LevelRow('OK', 'otherwise')),
    (KeyRow(('Gaps', 'Longest gap (s)'), 'intervals longer than 1.5 `dt`, the longest'),
     KeyRow(('mu current', 'mu max'), 'interval / `dt`: the last and the largest'),
     KeyRow(('Last stamp (s)',), 'the newest stamp')))


POINTING_TASK = DiagnosticTask(
    POINTING, 'with `pat.enabled` only: the acquiring / tracking / lost supervisor '
    '(doc/pointing.md); the state is also on `pat_state`',
    (LevelRow('ERROR', 'lost: the lock tests declared a link that worked gone', 'lost'),
     LevelRow('WARN', 'acquiring: no light yet (expected after a start or `~/acquire`, a '
              'fault only if it lasts)', 'acquiring'),
     LevelRow('OK', 'tracking: the loop works', 'tracking'),
     LevelRow('OK', 'paused (`~/enable` false), in any state: a paused loop is what was '
              'asked for', 'paused (~/enable false) while <state>')),
    (KeyRow(('State', 'Time in state (s)'), 'acquiring, tracking or lost; the sample '
            'stamps since it began'),
     KeyRow(('Transitions',), 'state changes since the start (hand-overs, losses, forced '
            'searches, restarts)'),
     KeyRow(('Acquisitions', 'Losses', 'Re-acquisitions'), 'hand-overs from a cold '
            'search, losses the lock tests declared, hand-overs after a loss'),
     KeyRow(('Acquire requests',), 'searches forced by `~/acquire`'),
     KeyRow(('Last loss (stamp, s)',), 'the stamp of the sample at which the last loss '
            'was declared, `never` before one'),
     KeyRow(('Low samples in the lock window', 'Windowed NIS', 'NIS band'), 'the lock '
            'tests at the last sample: intensities below `pat.lock_level` of the last '
            '`pat.lock_window`, the summed NIS and its band (`none` without values)')))


def samples_frequency_task(target: str) -> DiagnosticTask:
    """Return a simulator's 'output frequency' task, its target frequency in words."""
    return DiagnosticTask(
        OUTPUT_FREQUENCY, f'FrequencyStatus of the samples taken (published, or dropped by '
        f'a blockage), against {target}, tolerance 0.5', FREQUENCY_LEVELS, FREQUENCY_KEYS)


def readings_frequency_task() -> DiagnosticTask:
    """Return the driver's 'output frequency' task: the readings published."""
    return DiagnosticTask(
        OUTPUT_FREQUENCY, 'FrequencyStatus of the readings published, against `rate`, '
        'tolerance 0.5; only while a meter is open', FREQUENCY_LEVELS, FREQUENCY_KEYS)


POWER_METER_TASK = DiagnosticTask(
    POWER_METER, "the meter's state, `hardware_id` = the resource; outside the active "
    'state the message starts with the state (`inactive: ...`)',
    (LevelRow('ERROR', 'not connected'),
     LevelRow('WARN', 'readings skipped or converted, or the device reported errors, since '
              'the last update; or no meter open (unconfigured: "unconfigured: not '
              'reading")'),
     LevelRow('OK', 'otherwise')),
    (KeyRow(('Lifecycle state',), 'the state, while no meter is open (then the only key)'),
     KeyRow(('connected', 'resource', 'identity'),
            'connection state, the VISA resource, the `*IDN?` answer'),
     KeyRow(('unit', 'device_unit'), 'the unit asked for, the unit the meter reports'),
     KeyRow(('readings_per_s', 'published'),
            'readings published per second since the previous message, in all'),
     KeyRow(('skipped', 'skipped_<reason>'), 'readings not published, in all and by reason: '
            + _reasons(SKIP_REASONS)),
     KeyRow(('unit_converted',), 'readings converted from another unit to mW'),
     KeyRow(('latency_last_ms', 'latency_mean_ms', 'latency_max_ms'),
            'round trip of a reading query (ms)'),
     KeyRow(('connects', 'disconnects', 'connect_failures', 'retry_in_s'),
            'connection history; time to the next attempt (s)'),
     KeyRow(('device_errors', 'last_error'), 'what `SYST:ERR?` reported; the last error')))
