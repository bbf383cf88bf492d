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

"""The package's nodes by name, and a node started in-process with parameter overrides."""

import importlib
from pathlib import Path
import sys
from typing import Any, Dict, List, Mapping, Optional, Type, Union

from rclpy.context import Context
from rclpy.executors import Executor
from rclpy.node import Node
from rclpy.parameter import Parameter
import yaml

# executable name -> 'module:Class' (the console scripts of setup.py that are nodes)
NODES: Dict[str, str] = {
    'timescale_estimator': 'tskf_ros.nodes.timescale_estimator:TimescaleEstimator',
    'power_meter_simulator': 'tskf_ros.nodes.power_meter_simulator:PowerMeterSimulator',
    'power_meter_driver': 'tskf_ros.nodes.power_meter_driver:PowerMeterDriver',
    'led_link_simulator': 'tskf_ros.nodes.led_link_simulator:LedLinkSimulator',
    'alignment': 'tskf_ros.nodes.alignment:Alignment',
}

Parameters = Union[Mapping[str, Any], list]


def node_class(name: str) -> Type[Node]:
    """Return the Node class of one of the package's executables (see NODES)."""
    if name not in NODES:
        raise ValueError(f'{name!r} is not a node of tskf_ros (one of: {", ".join(NODES)})')
    module, cls = NODES[name].split(':')
    return getattr(importlib.import_module(module), cls)


def _flatten(values: Mapping[str, Any], prefix: str = '') -> Dict[str, Any]:
    """Nested YAML mappings as dotted parameter names (a.b: 1), as rcl reads them."""
    out: Dict[str, Any] = {}
    for key, value in values.items():
        if isinstance(value, Mapping):
            out.update(_flatten(value, f'{prefix}{key}.'))
        else:
            out[f'{prefix}{key}'] = value
    return out


def file_parameters(params_file: Union[str, Path], node_name: str) -> Dict[str, Any]:
    """
    Return {name: value} of a ROS 2 parameter file for a node named node_name.

    The sections that apply to a node in the root namespace, in the file's order (later
    ones win): /**, /**/<name>, /<name> and <name>.
    """
    data = yaml.safe_load(Path(params_file).read_text()) or {}
    if not isinstance(data, Mapping):
        raise ValueError(f'{params_file}: not a ROS 2 parameter file (no node sections)')
    out: Dict[str, Any] = {}
    for key, section in data.items():
        if str(key) in ('/**', f'/**/{node_name}', f'/{node_name}', node_name):
            if not isinstance(section, Mapping) or 'ros__parameters' not in section:
                raise ValueError(f'{params_file}: section {key} has no ros__parameters')
            out.update(_flatten(section['ros__parameters']))
    return out


def overrides(parameters: Optional[Parameters] = None,
              params_file: Optional[Union[str, Path]] = None,
              node_name: str = '') -> List[Parameter]:
    """
    Return rclpy Parameters: those of a params file for node_name, updated by parameters.

    parameters is a {name: value} mapping or a list of rclpy Parameters; they win over the
    file's.
    """
    merged: Dict[str, Parameter] = {}
    if params_file is not None:
        merged.update({k: Parameter(k, value=v)
                       for k, v in file_parameters(params_file, node_name).items()})
    if isinstance(parameters, Mapping):
        merged.update({k: Parameter(k, value=v) for k, v in parameters.items()})
    else:
        merged.update({p.name: p for p in parameters or []})
    return list(merged.values())


def start_in_process(node: Union[str, Type[Node]], context: Context,
                     executor: Optional[Executor] = None, *,
                     parameters: Optional[Parameters] = None,
                     params_file: Optional[Union[str, Path]] = None,
                     **kwargs: Any) -> Node:
    """
    Create a node (a name from NODES, or a Node class) in context; add it to executor.

    Parameter overrides come from params_file and parameters (see overrides); further
    keyword arguments go to the node's constructor (node_name, namespace, ...).
    """
    cls = node_class(node) if isinstance(node, str) else node
    # the name whose sections of params_file apply: the node's default name (NODE_NAME of
    # its module, as this package's nodes have) unless node_name is given
    name = kwargs.get('node_name') or getattr(sys.modules[cls.__module__], 'NODE_NAME',
                                              node if isinstance(node, str) else '')
    made = cls(context=context, parameter_overrides=overrides(parameters, params_file, name),
               **kwargs)
    if executor is not None:
        executor.add_node(made)
    return made
