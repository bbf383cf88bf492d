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
Each node declares exactly the parameters of its schema (config/schema/<node>.yaml).

The nodes are started in-process and asked, as `ros2 param list` and `ros2 param describe`
ask them (list_parameters, describe_parameters, get_parameters), what they declare; the
answers must be the schema's names, types, descriptions, ranges, read-only flags and
defaults.  The schema's defaults are checked against the dataclasses of the core they
configure, and the node pages must render the schema's table.  The reader itself
(messages/parameter_schema.py) is checked on small schemas written here.
"""

from dataclasses import fields
import math
from pathlib import Path

import numpy as np
import pytest
from rclpy.parameter import Parameter

from tskf_ros.core.linear_models import owc
from tskf_ros.led.alignment_config import AlignmentConfig
from tskf_ros.led.led_link import LedLinkConfig
from tskf_ros.led.pat_config import PatConfig
from tskf_ros.messages.parameter_schema import (load_schema, ParameterError, parse_schema,
                                                SchemaFormatError)
from tskf_ros.messages.parameters import IGNORED, IGNORED_PREFIX
from tskf_ros.nodes.alignment import Alignment
from tskf_ros.nodes.led_link_simulator import LedLinkSimulator
from tskf_ros.nodes.power_meter_driver import PowerMeterDriver
from tskf_ros.nodes.power_meter_simulator import PowerMeterSimulator
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator
from tskf_ros.owc.meter_settings import MeterConfig, ScpiCommands
from tskf_ros.owc.vibrating_link import OwcLinkConfig

REPO = Path(__file__).resolve().parents[2]
NODES = {'timescale_estimator': TimescaleEstimator,
         'power_meter_simulator': PowerMeterSimulator,
         'power_meter_driver': PowerMeterDriver,
         'led_link_simulator': LedLinkSimulator,
         'alignment': Alignment}


def declared(node):
    """Return the names the node lists, without rclpy's own and the QoS overrides."""
    names = node.list_parameters([], 0).names
    return [n for n in names if n not in IGNORED and not n.startswith(IGNORED_PREFIX)]


@pytest.mark.parametrize('name', sorted(NODES))
def test_the_node_declares_its_schema(ros_context, name):
    schema = load_schema(name)
    node = NODES[name](context=ros_context)
    try:
        names = declared(node)
        assert sorted(names) == sorted(schema.names)
        values = {p.name: p.value for p in node.get_parameters(list(schema.names))}
        for spec, d in zip(schema.parameters.values(),
                           node.describe_parameters(list(schema.names))):
            assert d.name == spec.name
            assert d.type == spec.ros_type.value, spec.name
            assert d.description == spec.description, spec.name
            assert d.read_only == spec.read_only, spec.name
            assert not d.dynamic_typing, spec.name
            rng = spec.closed_range()
            ranges = [(r.from_value, r.to_value) for r in
                      list(d.floating_point_range) + list(d.integer_range)]
            assert ranges == ([] if rng is None else [rng]), spec.name
            value = values[spec.name]
            default = spec.default
            if isinstance(default, list):
                assert list(value) == default, spec.name
            else:
                assert value == default and type(value) is type(default), spec.name
    finally:
        node.destroy_node()


@pytest.mark.parametrize('name', sorted(NODES))
def test_the_node_page_renders_the_schema(name):
    page = (REPO / 'doc' / 'nodes' / f'{name}.md').read_text()
    assert f'```{{parameter-table}} {name}\n```' in page
    # no hand-written parameter table left beside the generated one
    assert not [line for line in page.splitlines() if line.startswith('| parameter |')]


def test_the_estimator_defaults_are_cais_model_3():
    model, values = owc(), load_schema('timescale_estimator').defaults()
    for key in ('A', 'C', 'D', 'G', 'Q', 'R', 'x0', 'P0'):
        np.testing.assert_array_equal(values[key], np.ravel(getattr(model, key)), err_msg=key)
    assert values['B'] == [] and values['model_name'] == model.name
    assert values['state_names'] == list(model.state_names)


@pytest.mark.parametrize('name, config, prefix', [
    ('power_meter_simulator', OwcLinkConfig(), ''),
    ('led_link_simulator', LedLinkConfig(), ''),
    ('alignment', AlignmentConfig(), ''),
    ('alignment', PatConfig(), 'pat.'),
    ('power_meter_driver', MeterConfig(), ''),
    ('power_meter_driver', ScpiCommands(), 'scpi_')])
def test_the_schema_defaults_are_the_dataclass_defaults(name, config, prefix):
    values = load_schema(name).defaults()
    for f in fields(config):
        if f.name in ('commands', 'pat'):     # pat: the row of PatConfig
            continue
        want = getattr(config, f.name)
        want = [float(v) for v in want] if isinstance(want, tuple) else want
        assert values[prefix + f.name] == want, f.name


@pytest.mark.parametrize('params, name', [
    ('owc_estimator.yaml', 'timescale_estimator'),
    ('reference_estimator.yaml', 'timescale_estimator'),
    ('drogue_estimator.yaml', 'timescale_estimator'),
    ('power_meter_simulator.yaml', 'power_meter_simulator'),
    ('power_meter_driver.yaml', 'power_meter_driver'),
    ('led_link_simulator.yaml', 'led_link_simulator'),
    ('alignment.yaml', 'alignment')])
def test_the_shipped_parameter_files_pass_their_schema(params, name):
    from tskf_ros.messages.parameters import parameter_values
    values = parameter_values(REPO / 'config' / params, load_schema(name))
    assert set(values) == set(load_schema(name).names)


def test_parameters_given_at_start_are_known_and_integers_are_doubles(ros_context):
    node = TimescaleEstimator(context=ros_context, parameter_overrides=[
        Parameter('period', value=2), Parameter('x0', value=[1]),
        Parameter('measurement_range', value=[0, 500])])
    try:
        assert {'period', 'x0', 'measurement_range'} <= node.parameters_given
        assert 'gate' not in node.parameters_given
        assert node.get_parameter('period').value == 2.0
        assert node.get_parameter('x0').value == [1.0]
        assert node.config.session.period == 2.0
        # later: an integer for a double is taken as the double; a choice outside one_of<>
        # and an array of the wrong size are refused with the schema's reason
        assert node.set_parameters([Parameter('gate', value=4)])[0].successful
        assert node.get_parameter('gate').value == 4.0
        result = node.set_parameters([Parameter('transition', value='rk4')])[0]
        assert not result.successful
        assert result.reason == "transition must be one of euler, exact, got 'rk4'"
        result = node.set_parameters([Parameter('measurement_range', value=[1.0, 2.0, 3.0])])[0]
        assert not result.successful and 'fewer than 3 entries' in result.reason
        result = node.set_parameters([Parameter('period', value=0.0)])[0]
        assert not result.successful and 'out of range' in result.reason
        assert node.get_parameter('period').value == 2.0
    finally:
        node.destroy_node()


def test_integers_for_a_double_array_from_the_set_parameters_service(ros_context):
    # the service's request carries an integer array as array.array('q'), not a list
    node = TimescaleEstimator(context=ros_context)
    try:
        def as_sent(name, value):
            return Parameter.from_parameter_msg(Parameter(name, value=value).to_parameter_msg())
        assert node.set_parameters([as_sent('x0', [2])])[0].successful
        assert node.get_parameter('x0').value == [2.0]
        result = node.set_parameters([as_sent('queue_depth', [1.0, 2.0])])[0]
        assert not result.successful and 'array(' not in result.reason
    finally:
        node.destroy_node()


@pytest.mark.parametrize('override, why', [
    (Parameter('transition', value='rk4'), "transition must be one of euler, exact, got 'rk4'"),
    (Parameter('period', value=-1.0), 'period = -1 is out of range: it must be within '
     '[1e-6, 3600]'),
    (Parameter('period', value='fast'), "period must be a number, got 'fast'"),
    (Parameter('queue_depth', value=2.5), 'queue_depth must be an integer, got 2.5')])
def test_a_bad_value_at_start_is_one_parameter_error(ros_context, override, why):
    with pytest.raises(ParameterError) as info:
        TimescaleEstimator(context=ros_context, parameter_overrides=[override])
    assert str(info.value) == why


@pytest.mark.parametrize('node, override, why', [
    (TimescaleEstimator, Parameter('smoothing_lag', value=True),
     'smoothing_lag must be an integer, got True'),
    (Alignment, Parameter('pat.hold_samples', value=True),
     'pat.hold_samples must be an integer, got True'),
    # the number printed with every digit: 1e8 would hide why it is out of range
    (Alignment, Parameter('pat.hold_samples', value=100000001),
     'pat.hold_samples = 100000001 is out of range: it must be within [0, 1e8]'),
    # rclpy publishes a parameter given at start before any check of the node: an integer
    # beyond int64 ended in "SystemError: <function ParameterValue.double_value ...>"
    (TimescaleEstimator, Parameter('queue_depth', value=2 ** 63),
     'queue_depth = 9223372036854775808 is out of range: it must be within [1, 100000]'),
    (PowerMeterSimulator, Parameter('seed', value=2 ** 63),
     'seed = 9223372036854775808 is out of range: it must be within '
     '[0, 9223372036854775807]'),
    (LedLinkSimulator, Parameter('seed', value=-2 ** 63 - 1),
     'seed = -9223372036854775809 is out of range: it must be within '
     '[0, 9223372036854775807]'),
    # an integer for a double, beyond int64 (rclpy sends it as one) or beyond any double
    (TimescaleEstimator, Parameter('period', value=2 ** 63),
     'period = 9223372036854775808 is out of range: it must be within [1e-6, 3600]'),
    (TimescaleEstimator, Parameter('period', value=2 ** 1100),
     f'period = {2 ** 1100} is out of range: it must be within [1e-6, 3600]'),
    (Alignment, Parameter('gain', value=2 ** 63),
     'gain = 9223372036854775808 is out of range: it must be within '
     '[-9223372036854775808, 9223372036854775807] (a 64-bit integer)'),
    (TimescaleEstimator, Parameter('x0', value=[1, 2 ** 63]),
     'x0 has an entry out of range (9223372036854775808): each must be within '
     '[-9223372036854775808, 9223372036854775807] (a 64-bit integer)'),
    (TimescaleEstimator, Parameter('frame_id', value=2 ** 64),
     'frame_id must be a string, got 18446744073709551616'),
    # doubles: the largest, nan and inf are refused by the range, or the node's own check
    (TimescaleEstimator, Parameter('period', value=1e308),
     'period = 1e308 is out of range: it must be within [1e-6, 3600]'),
    (TimescaleEstimator, Parameter('gate', value=math.nan), 'gate must be finite, got nan'),
    (TimescaleEstimator, Parameter('gate', value=math.inf), 'gate must be finite, got inf')])
def test_a_bool_for_an_integer_and_numbers_out_of_range_are_refused_at_start(
        ros_context, node, override, why):
    # before: `-p pat.hold_samples:=true` and `-p smoothing_lag:=true` started (exit 0)
    with pytest.raises(ParameterError) as info:
        node(context=ros_context, parameter_overrides=[override])
    assert str(info.value) == why


@pytest.mark.parametrize('override, why', [
    # an integer no double holds stays an integer (the pre-set callback cannot refuse):
    # rclpy's type check refuses it
    (Parameter('gate', value=2 ** 1100),
     "Wrong parameter type, expected 'Type.DOUBLE' got 'Type.INTEGER'"),
    (Parameter('x0', value=[2 ** 1100]),
     "Wrong parameter type, expected 'Type.DOUBLE_ARRAY' got 'Type.INTEGER_ARRAY'"),
    # one a double holds is made one, and refused by the descriptor's range (rclpy's text)
    (Parameter('status_period', value=2 ** 63), 'Parameter status_period out of range '
     'Min: 0.0, Max: 1000000.0, value: 9.223372036854776e+18'),
    (Parameter('measurement_range', value=[0.0, math.nan]),
     'measurement_range must be empty or [lo, hi] with finite lo < hi, got [0.0, nan]'),
    (Parameter('Q', value=[math.inf]), 'Q has non-finite entries'),
    (Parameter('smoothing_lag', value=2 ** 63), 'Trying to set a read-only parameter: '
     'smoothing_lag.')])
def test_a_number_out_of_reach_set_at_run_time_is_refused_with_the_reason(
        ros_context, override, why):
    # before: the integers too big for a double ended in an OverflowError traceback from
    # the pre-set callback; the node keeps its values
    node = TimescaleEstimator(context=ros_context)
    try:
        before = node.get_parameter(override.name).value
        result = node.set_parameters([override])[0]
        assert not result.successful and result.reason == why
        assert node.get_parameter(override.name).value == before
    finally:
        node.destroy_node()


@pytest.mark.parametrize('name', sorted(NODES))
def test_every_integer_parameter_refuses_a_bool(name):
    # Python's bool is an int, and rclpy's INTEGER type check takes it
    schema = load_schema(name)
    ints = [p for p in schema.parameters.values() if p.type_name in ('int', 'int_array')]
    assert ints
    for spec in ints:
        value, kind = (True, 'an integer') if spec.type_name == 'int' else \
            ([True, False], 'a list of integers')
        assert spec.problem(value) == f'{spec.name} must be {kind}, got {value!r}'
        assert schema.refusal([Parameter(spec.name, value=value)])


def test_a_read_only_parameter_stays_read_only(ros_context):
    node = PowerMeterSimulator(context=ros_context)
    try:
        assert not node.set_parameters([Parameter('rate', value=2.0)])[0].successful
        assert node.set_parameters([Parameter('publish_invalid', value=True)])[0].successful
        assert node.config.publish_invalid is True
    finally:
        node.destroy_node()


SMALL = """
demo:
  gain:
    type: double
    default_value: 1
    description: "a gain"
    validation:
      gt<>: [0.0]
  mode:
    type: string
    default_value: a
    validation:
      one_of<>: [["a", "b"]]
  diagnostic_updater:
    period:
      type: double
      default_value: 1.0
      read_only: true
      validation:
        bounds<>: [0.01, 3600.0]
  limits:
    type: double_array
    default_value: [-1, 1]
    validation:
      fixed_size<>: [2]
      element_bounds<>: [-10.0, 10.0]
"""


def test_a_schema_reads_nested_names_and_generate_parameter_librarys_validations():
    import yaml
    schema = parse_schema(yaml.safe_load(SMALL))
    assert schema.node == 'demo'
    assert schema.names == ('gain', 'mode', 'diagnostic_updater.period', 'limits')
    assert schema.defaults() == {'gain': 1.0, 'mode': 'a', 'diagnostic_updater.period': 1.0,
                                 'limits': [-1.0, 1.0]}
    period = schema.parameters['diagnostic_updater.period']
    d = period.descriptor()
    assert d.read_only and d.floating_point_range[0].from_value == 0.01
    assert d.floating_point_range[0].to_value == 3600.0
    # gt<> is open: no closed range in the descriptor, said in its constraints
    gain = schema.parameters['gain'].descriptor()
    assert not gain.floating_point_range and gain.additional_constraints == '> 0'
    assert schema.check({'gain': 2}) == {'gain': 2.0}
    for values, why in (({'gain': 0.0}, 'gain = 0 is out of range: it must be > 0'),
                        ({'gain': math.nan}, 'gain must be finite, got nan'),
                        ({'mode': 'c'}, "mode must be one of a, b, got 'c'"),
                        ({'limits': [1.0]}, 'limits must have 2 entries, got [1.0]'),
                        ({'limits': [0.0, 11.0]},
                         'limits must have each entry within [-10, 10], got [0.0, 11.0]'),
                        ({'other': 1}, 'demo has no parameter(s) other')):
        with pytest.raises(ParameterError) as info:
            schema.check(values)
        assert str(info.value) == why
    rows = {r.name: r for r in schema.table_rows()}
    assert rows['limits'].constraints == '2 entries; each -10 to 10'
    assert rows['diagnostic_updater.period'].read_only
    assert rows['limits'].default == '[-1, 1]'


@pytest.mark.parametrize('text, why', [
    ('demo:\n  x:\n    type: float\n', "type 'float' is not one of"),
    ('demo:\n  x:\n    type: double\n    validation:\n      positive<>: []\n',
     "unknown validation 'positive<>'"),
    ('demo:\n  x:\n    type: double\n    default_value: 5.0\n    validation:\n'
     '      bounds<>: [0.0, 1.0]\n', 'x = 5 is out of range'),
    ('demo:\n  x:\n    type: int\n    default_value: 1.5\n', 'x must be an integer'),
    ('demo:\n  x:\n    type: int\n    descripton: typo\n', 'unknown key(s) descripton'),
    ('a: {}\nb: {}\n', 'one top-level key')])
def test_a_malformed_schema_is_refused_with_the_reason(text, why):
    import yaml
    with pytest.raises(SchemaFormatError) as info:
        parse_schema(yaml.safe_load(text), 'demo.yaml')
    assert why in str(info.value)


def test_every_shipped_schema_is_a_node_of_this_package():
    shipped = sorted(p.stem for p in (REPO / 'config' / 'schema').glob('*.yaml'))
    assert shipped == sorted(NODES)
    for name in shipped:
        assert load_schema(name).node == name


def test_a_number_beyond_what_a_parameter_carries_is_refused_by_the_schema():
    # what an offline tool checks (schema.check: a parameter file, --set) says the same
    import yaml
    schema = parse_schema(yaml.safe_load(SMALL + '  count:\n    type: int\n    '
                                         'default_value: 1\n  ids:\n    type: int_array\n'
                                         '    default_value: [1]\n'))
    for values, why in (
            ({'count': 2 ** 63}, 'count = 9223372036854775808 is out of range: it must be '
             'within [-9223372036854775808, 9223372036854775807] (a 64-bit integer)'),
            ({'ids': [1, -2 ** 63 - 1]}, 'ids has an entry out of range '
             '(-9223372036854775809): each must be within [-9223372036854775808, '
             '9223372036854775807] (a 64-bit integer)'),
            ({'gain': 2 ** 1024}, f'gain = {2 ** 1024} is out of range: it must be within '
             '[-1.7976931348623157e308, 1.7976931348623157e308] (a double)')):
        with pytest.raises(ParameterError) as info:
            schema.check(values)
        assert str(info.value) == why
    assert schema.check({'count': 2 ** 63 - 1, 'gain': 2 ** 63}) == {
        'count': 2 ** 63 - 1, 'gain': 9.223372036854775808e18}
