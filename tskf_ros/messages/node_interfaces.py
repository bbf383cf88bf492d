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

"""Each node's topics, services and diagnostic tasks, declared from the interface constants."""

from tskf_ros.messages import alignment_interface as align
from tskf_ros.messages import estimator_interface as estimator
from tskf_ros.messages.conversions import STATES_TYPE
from tskf_ros.messages.diagnostic_tasks import (ALIGNER_TASK, ALIGNMENT_TIME_SCALE_TASK,
                                                ESTIMATOR_TIME_SCALE_TASK, FILTER_HEALTH_TASK,
                                                INPUT_FREQUENCY_TASK, POINTING_TASK,
                                                POWER_METER_TASK,
                                                readings_frequency_task,
                                                samples_frequency_task, TIMESTAMP_DELAY_TASK)
from tskf_ros.messages.interface_spec import (IN, LIFECYCLE_SERVICES, NodeInterface, OUT,
                                              qos_summary, Service, Topic, TRANSITION_EVENT)
from tskf_ros.messages.names import RESET_SERVICE, TRUTH_TOPIC
from tskf_ros.messages.qos import (DEFAULT_DEPTH, DIAGNOSTICS_TOPIC, reliable_qos,
                                   SENSOR_OUTPUT_QOS, TRUTH_QOS)

__all__ = ['ALIGNMENT', 'INTERFACES', 'interface', 'LED_LINK_SIMULATOR', 'POWER_METER_DRIVER',
           'POWER_METER_SIMULATOR', 'RESET_SERVICE', 'SENSOR_TYPE', 'TIMESCALE_ESTIMATOR',
           'TRUTH_TOPIC', 'TRUTH_TYPE']

# the stamped scalar of the power meters and the photodiode (doc/interfaces.md: why)
SENSOR_TYPE = 'sensor_msgs/msg/Illuminance'
TRUTH_TYPE = STATES_TYPE
RESET_TYPE = 'std_srvs/srv/Trigger'

SENSOR_QOS = qos_summary(SENSOR_OUTPUT_QOS) + ' (sensor data)'
INPUT_QOS = ('best effort, keep last `queue_depth` (matches reliable and best-effort '
             'publishers)')
# the estimates, the base command, /diagnostics (rclpy's and forward_command_controller's)
RELIABLE_QOS = qos_summary(reliable_qos(DEFAULT_DEPTH))
DIAGNOSTICS = Topic(DIAGNOSTICS_TOPIC, estimator.DIAGNOSTICS_TYPE, OUT, RELIABLE_QOS,
                    'one status per diagnostic task of the node, every '
                    '`diagnostic_updater.period` s')
POWER_CONTENT = ('header.stamp = the sample time, `illuminance` = power (mW), `variance` = '
                 '{variance}, frame `frame_id`')

ESTIMATE_CONTENT = {
    'predicted': "Table 3's predictor xhat(t_k), P(t_k) from the data before t_k, stamped "
                 't_k; `data[2]` = the graininess of the step into t_k',
    'corrected': 'x(t_k given t_k), stamped t_k, published when the sample after t_k '
                 'arrives',
    'revised': 'after a late sample: every estimate recomputed from its left neighbour on, '
               'predicted and corrected (the kind in `layout.dim[0].label`)',
    'smoothed': 'with `smoothing_lag` L > 0 only: the fixed-lag smoothed x(t_k given '
                't_{k+L}), L steps behind',
}

TIMESCALE_ESTIMATOR = NodeInterface(
    estimator.NODE_NAME,
    (Topic(estimator.MEASUREMENT_TOPIC, estimator.DEFAULT_MEASUREMENT_TYPE, IN, INPUT_QOS,
           'y and, where the type has one, its variance; `measurement_type` is one of '
           + ', '.join(estimator.INPUT_TYPES) + ' (a std_msgs type is stamped on arrival). '
           'Launch files remap it to `received_power`',
           type_parameter='measurement_type'),
     Topic(estimator.INPUT_TOPIC, estimator.INPUT_TYPE, IN, INPUT_QOS,
           "the model's input u: slot i = u[i] (linear.x, .y, .z, angular.x, .y, .z), held "
           'from its stamp until the next input'),
     *(Topic(topic, estimator.output_type(key), OUT,
             RELIABLE_QOS + '; `qos_overrides`',
             ESTIMATE_CONTENT[key],
             only_with={'smoothing_lag': 1} if key == 'smoothed' else {})
       for key, topic in estimator.OUTPUT_TOPICS.items()),
     DIAGNOSTICS),
    (Service(RESET_SERVICE, RESET_TYPE,
             'restart the session from `x0`, `P0` (counted as `Resets (service)`)'),),
    (INPUT_FREQUENCY_TASK, TIMESTAMP_DELAY_TASK, FILTER_HEALTH_TASK,
     ESTIMATOR_TIME_SCALE_TASK),
    purpose='the time-scale Kalman filter on a stream of stamped scalar samples')

POWER_METER_SIMULATOR = NodeInterface(
    'power_meter_simulator',
    (Topic(estimator.POWER_TOPIC, SENSOR_TYPE, OUT, SENSOR_QOS,
           POWER_CONTENT.format(variance='`noise_std`^2 (mW^2)')),
     Topic(TRUTH_TOPIC, TRUTH_TYPE, OUT, qos_summary(TRUTH_QOS),
           'one joint (`angle_name`): theta at `position` (rad), for every sample, gaps '
           'included'),
     DIAGNOSTICS),
    (),
    (samples_frequency_task('`rate` x `time_factor`'),),
    purpose="Cai et al.'s vibrating, intermittent OWC link, as a power meter driver would "
    'publish it')

LED_LINK_SIMULATOR = NodeInterface(
    'led_link_simulator',
    (Topic(align.INPUT_TOPIC, SENSOR_TYPE, OUT, SENSOR_QOS,
           '`illuminance` = photodiode voltage V_d (V), `variance` = `noise`^2 (V^2), '
           'header.stamp = the sample time, frame `frame_id`'),
     Topic(TRUTH_TOPIC, TRUTH_TYPE, OUT, qos_summary(TRUTH_QOS),
           'joints `incidence` (phi), `base`, `transmitter`: angles at `position` (rad); '
           'with `axes` 2 the two `pan_tilt.joints` (the receiver, scan included), '
           '`source_azimuth`, `source_elevation` and `off_axis`, the angle between the '
           "receiver's boresight and the source (rad)"),
     Topic(align.COMMAND_TOPIC, align.COMMAND_TYPE, IN, RELIABLE_QOS,
           '`[base angle]` (rad), as a ros2_control forward_command_controller takes it; '
           'with `axes` 2 `[pan, tilt]` (rad) in the order of `pan_tilt.joints`'),
     DIAGNOSTICS),
    (),
    (samples_frequency_task('`time_factor` / `dt` (none in lockstep)'),),
    purpose="Solanki et al.'s LED link with a commanded rotating receiver base (axes 2: "
    'a pan-tilt mount')

POWER_METER_DRIVER = NodeInterface(
    'power_meter_driver',
    (Topic(estimator.POWER_TOPIC, SENSOR_TYPE, OUT, SENSOR_QOS + '; a lifecycle publisher',
           POWER_CONTENT.format(variance='the `variance` parameter (0: unknown)')
           + ', stamped at the midpoint of the query'),
     DIAGNOSTICS,
     TRANSITION_EVENT),
    (*LIFECYCLE_SERVICES,
     Service(RESET_SERVICE, RESET_TYPE,
             'close the connection and reconnect at once, without waiting for the '
             'backoff')),
    (readings_frequency_task(), POWER_METER_TASK),
    note='a lifecycle node: its lifecycle services and ~/transition_event come from '
    'rclpy.lifecycle',
    purpose='a real optical power meter (Thorlabs PM100 or any SCPI meter) over VISA, '
    'published as the simulator does')

ALIGNMENT = NodeInterface(
    align.NODE_NAME,
    (Topic(align.INPUT_TOPIC, SENSOR_TYPE, IN, INPUT_QOS,
           '`illuminance` = photodiode voltage V_d (V), header.stamp = the sample time t_k'),
     *(Topic(align.OUTPUT_TOPICS[key], align.OUTPUT_TYPES[key], OUT,
             'reliable, keep last `queue_depth`', content)
       for key, content in (
           ('predicted', 'the estimate layout (doc/interfaces.md), EKF only and, with '
                         '`pat.enabled`, '
                         'only while tracking: x^f_k, P^f_k of eq. (13)-(14) at t_k, kind '
                         '`predicted`, states `x1_intensity_V,x2_scan_mean_rad`: `data[3]` '
                         '= x1 (V), `data[4]` = x2 (rad), `data[5:9]` = P row-major (V^2, '
                         'V rad, rad^2); `data[2]` = mu = t_k - t_{k-1} (s; 0 at the '
                         'first sample of a run)'),
           ('corrected', 'as `estimate/predicted`, after the update (18)-(20), kind '
                         '`corrected`, published with the command; the same mu (the '
                         'update does not depend on the step out of t_k). With `axes` 2 '
                         "both are the conical-scan EKF's, states `x1_intensity_V,"
                         'd_cross_elevation_rad,d_elevation_rad,'
                         'b_cross_elevation_rad_per_step,b_elevation_rad_per_step`, P to '
                         "match (no prediction at the supervisor's hand-over)"))),
     Topic(align.COMMAND_TOPIC, align.COMMAND_TYPE, OUT, RELIABLE_QOS,
           '`[base angle]` (rad), as forward_command_controller expects; with `axes` 2 '
           '`[pan, tilt]` (rad) in the order of `pan_tilt.joints`, which label '
           '`layout.dim[0]`'),
     Topic(align.PAT_STATE_TOPIC, align.PAT_STATE_TYPE, OUT,
           qos_summary(align.pat_state_qos()) + ' (latched)',
           '`data` = `acquiring`, `tracking` or `lost` (`disabled` with `pat.enabled` '
           'false), at start and on each transition'),
     DIAGNOSTICS),
    (Service(RESET_SERVICE, RESET_TYPE, 'restart the aligner from its initial state (with '
             '`pat.enabled`: in `pat.start`)'),
     Service('~/enable', 'std_srvs/srv/SetBool',
             'false pauses everything, the supervisor too: intensities are counted and '
             'dropped, no step, no command, no state change; true resumes (the EKF then '
             'predicts over the pause)'),
     Service('~/acquire', 'std_srvs/srv/Trigger',
             'with `pat.enabled`: force a new cold search around the current base angle '
             '(acquiring, on `pat_state`); without the supervisor it answers success '
             'false')),
    (INPUT_FREQUENCY_TASK, TIMESTAMP_DELAY_TASK, ALIGNER_TASK, ALIGNMENT_TIME_SCALE_TASK,
     POINTING_TASK),
    purpose='LED active alignment: the scanning EKF or a baseline, commanding the base; '
    'with axes 2 the conical-scan EKF commanding a pan-tilt mount')

# node (executable) name -> its interface
INTERFACES = {i.node: i for i in (TIMESCALE_ESTIMATOR, POWER_METER_SIMULATOR,
                                  POWER_METER_DRIVER, LED_LINK_SIMULATOR, ALIGNMENT)}


def interface(node: str) -> NodeInterface:
    """Return the declared interface of a node of the package (ValueError if none)."""
    if node not in INTERFACES:
        raise ValueError(f'{node!r} is not a node of tskf_ros (one of: '
                         f'{", ".join(INTERFACES)})')
    return INTERFACES[node]
