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

"""Which topics of a bag a replay reads: the measurement y and the input u, and what it assumed."""

from typing import Optional

from tskf_ros.bag.reader import BagError, BagReader
from tskf_ros.messages.estimator_interface import (BAG_INPUT_TOPIC, BAG_POWER_TOPIC,
                                                   INPUT_TYPE, INPUT_TYPES)

__all__ = ['choose_input_topic', 'choose_topic', 'InputError']


class InputError(BagError):
    """The bag has no usable measurement topic, or it has an unsupported type."""


def choose_topic(reader: BagReader, topic: Optional[str],
                 default: str = BAG_POWER_TOPIC) -> tuple[str, str, list]:
    """
    Pick the measurement topic and its type; return (topic, type, assumptions).

    Without --topic: `default` (/received_power) if present, else the only topic of a
    known type.
    """
    assumptions = []
    if topic is None:
        if default in reader.topics:
            topic = default
        else:
            known = [t for t, i in reader.topics.items() if i.msgtype in INPUT_TYPES]
            if len(known) != 1:
                raise InputError(
                    f'{reader.path}: no {default} topic and '
                    f'{"no" if not known else len(known)} stamped scalar topics '
                    f'({", ".join(known) or "none"}); choose one with --topic')
            topic = known[0]
            assumptions.append(f'no {default}: using {topic}, the only stamped scalar '
                               'topic of the bag')
    info = reader.topics.get(topic)
    if info is None:
        raise InputError(f'{reader.path}: no topic {topic} (topics: '
                         f'{", ".join(sorted(reader.topics)) or "none"})')
    if info.msgtype not in INPUT_TYPES:
        raise InputError(f'{reader.path}: topic {topic} has type {info.msgtype or "unknown"}, '
                         f'not one this replay takes ({", ".join(INPUT_TYPES)})')
    kind = INPUT_TYPES[info.msgtype]
    field_text = f'{info.msgtype}.{kind.value}'
    assumptions.append(f'{topic} ({field_text}) is the measurement y of the model')
    if kind.variance is None and kind.stamped:
        assumptions.append(f'{info.msgtype} has no variance field: variance 0 (unknown)')
    if not kind.stamped:
        assumptions.append(f"WARNING: {info.msgtype} has no header stamp: the bag's log "
                           '(receive) time is used as the sample time, so mu includes '
                           'transport and recording jitter')
    if reader.storage == 'sqlite3':
        assumptions.append('sqlite3 storage (older rosbag2): read with rosbags')
    return topic, info.msgtype, assumptions


def choose_input_topic(reader: BagReader, topic: Optional[str]) -> tuple[str, list]:
    """
    Pick the input u's topic; return (topic or '', assumptions).

    Without --input-topic: /input if the bag has it, else none.
    """
    if topic is None:
        if BAG_INPUT_TOPIC not in reader.topics:
            return '', []
        topic = BAG_INPUT_TOPIC
    info = reader.topics.get(topic)
    if info is None:
        raise InputError(f'{reader.path}: no input topic {topic} (topics: '
                         f'{", ".join(sorted(reader.topics)) or "none"})')
    if info.msgtype != INPUT_TYPE:
        raise InputError(f'{reader.path}: input topic {topic} has type '
                         f'{info.msgtype or "unknown"}, not {INPUT_TYPE}')
    return topic, [f'{topic} ({INPUT_TYPE}, slot i = u[i]) is the input u of the model, held '
                   'from each stamp to the next (zero-order hold)']
