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

"""Whether a bag was recorded for the estimator model of the parameters: inputs and truth names."""

from typing import Optional, Sequence

from rclpy.serialization import deserialize_message

from tskf_ros.bag.message_types import DESERIALIZE_ERRORS, message_class
from tskf_ros.bag.reader import BagReader
from tskf_ros.bag.replay.topic_choice import InputError
from tskf_ros.core.linear_models import LinearModel
from tskf_ros.messages.conversions import STATES_TYPE

__all__ = ['check_model', 'model_mismatch', 'WrongModelError']


class WrongModelError(InputError):
    """A bag of another model than the parameters describe (its inputs or its truth)."""


def truth_names(reader: BagReader) -> dict[str, list[str]]:
    """Return {JointState topic: the joint names of its first message} (unreadable: none)."""
    out: dict[str, list[str]] = {}
    cls = None
    for topic in sorted(t for t, i in reader.topics.items() if i.msgtype == STATES_TYPE):
        cls = cls or message_class(STATES_TYPE)
        for raw in reader.messages([topic]):
            try:
                out[topic] = list(deserialize_message(raw.data, cls).name)
            except DESERIALIZE_ERRORS:
                pass
            break
    return out


def names_state(joint: str, states: Sequence[str]) -> bool:
    """Say whether a truth joint is a state: its name, or its name and a unit (theta_rad)."""
    return any(joint == s or joint.startswith(s + '_') for s in states)


def model_mismatch(reader: BagReader, input_topic: str, model: LinearModel) -> Optional[str]:
    """
    Return why the bag is not one of `model`, or None if nothing says so.

    A bag is of another model when it carries inputs u and the model has none (no B), the
    model has inputs and the bag none, or it has truth topics (JointState) of which no
    joint is a state of the model (state_names; a joint named with a unit suffix, such as
    displacement_m, is the state displacement).
    """
    m = model.B.shape[1] if model.B is not None else 0
    name = f'the model {model.name!r}'
    hint = 'give the parameters of its model (--params-file)'
    if input_topic and m == 0:
        return (f'{reader.path}: the bag has inputs u on {input_topic} but {name} has none '
                f'(B empty): a bag of another model; {hint}')
    if not input_topic and m > 0:
        return (f'{reader.path}: {name} has an input u (B is n x {m}) but the bag has no '
                f'input topic: a bag of another model; {hint}, or name it with --input-topic')
    truths = truth_names(reader)
    if truths and not any(names_state(n, model.state_names) for names in truths.values()
                          for n in names):
        found = '; '.join(f'{t}: {", ".join(n) or "no names"}' for t, n in truths.items())
        return (f'{reader.path}: its truth ({found}) names none of the states of {name} '
                f'({", ".join(model.state_names)}): a bag of another model; {hint}')
    return None


def check_model(reader: BagReader, input_topic: str, model: LinearModel) -> None:
    """Raise WrongModelError (one line) if the bag is not one of `model`."""
    why = model_mismatch(reader, input_topic, model)
    if why:
        raise WrongModelError(why)
