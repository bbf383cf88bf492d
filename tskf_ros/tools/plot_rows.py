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
Bag messages as rows of floats, streamed, and long series drawn as their envelope.

`stream` turns each message of the wanted topics into a row of floats as it is read
(`RowKind.read`) and drops the message, so that a bag of 1e7 messages costs 8 bytes a
number kept, not a deserialized message each.  A series longer than DRAWN points is drawn
as the least and the greatest value of each of DRAWN / 2 spans of consecutive points
(`envelope`, `band`), which keeps every excursion in sight.
"""

from array import array
from dataclasses import dataclass
from typing import Any, Callable, Iterator, Optional

import numpy as np
from rclpy.serialization import deserialize_message

from tskf_ros.bag.message_types import DESERIALIZE_ERRORS, message_class
from tskf_ros.bag.reader import BagError, BagReader

DRAWN = 8000        # points of a series drawn at most (about 5 per pixel of a panel)


@dataclass(frozen=True)
class RowKind:
    """How a message becomes a row: `read(msg)` gives `width` floats."""

    read: Callable[[Any], tuple]
    width: int


def messages(reader: BagReader, topics: set) -> Iterator[tuple[str, Any]]:
    """Yield (topic, message) of the wanted topics, deserialized; BagError (one line) if not."""
    classes: dict[str, Any] = {}
    for raw in reader.messages(topics):
        cls = classes.get(raw.msgtype) or classes.setdefault(raw.msgtype,
                                                             message_class(raw.msgtype))
        try:
            msg = deserialize_message(raw.data, cls)
        except DESERIALIZE_ERRORS as exc:
            raise BagError(f'{reader.path}: a message on {raw.topic} does not deserialize as '
                           f'{raw.msgtype} ({_first_line(exc)})') from None
        yield raw.topic, msg


def first(reader: BagReader, topic: str) -> Optional[Any]:
    """Return the first message on `topic`, or None if the bag has none."""
    if topic not in reader.topics:
        return None
    return next((msg for _, msg in messages(reader, {topic})), None)


def stream(reader: BagReader, kinds: dict[str, RowKind]) -> dict[str, np.ndarray]:
    """Return {topic: (N, width) array} of the wanted topics, one row per message read."""
    flat = {topic: array('d') for topic in kinds}
    for topic, msg in messages(reader, set(kinds)):
        try:
            row = kinds[topic].read(msg)
        except (ValueError, IndexError, KeyError) as exc:
            raise BagError(f'{reader.path}: a message on {topic} is not one this plot reads '
                           f'({_first_line(exc)})') from None
        flat[topic].extend(row)
    return {topic: np.frombuffer(values, dtype=float).reshape(-1, kinds[topic].width)
            for topic, values in flat.items()}


def _first_line(exc: BaseException) -> str:
    """Return the first line of an error's text, or its repr if it has none."""
    return str(exc).splitlines()[0] if str(exc) else repr(exc)


def _edges(n: int) -> np.ndarray:
    """Return the first index of each of DRAWN / 2 spans of n consecutive points."""
    return np.linspace(0, n, DRAWN // 2 + 1).astype(int)[:-1]


def envelope(t: np.ndarray, *ys: np.ndarray) -> tuple:
    """
    Return (t, y...) to draw: as given up to DRAWN points, else each span's least and greatest.

    Spans of consecutive points, DRAWN / 2 of them; each gives two points at its first t,
    its minimum, then its maximum.
    """
    if t.size <= DRAWN:
        return (t,) + ys
    edges = _edges(t.size)
    out = [np.column_stack([np.minimum.reduceat(y, edges),
                            np.maximum.reduceat(y, edges)]).ravel() for y in ys]
    return (np.repeat(t[edges], 2),) + tuple(out)


def band(t: np.ndarray, x: np.ndarray, s: np.ndarray) -> tuple:
    """Return (t, x - s, x + s) to fill: each span's lowest lower and highest upper edge."""
    if t.size <= DRAWN:
        return t, x - s, x + s
    edges = _edges(t.size)
    return t[edges], np.minimum.reduceat(x - s, edges), np.maximum.reduceat(x + s, edges)


def drawn_note(longest: int) -> str:
    """Return the title's line that says how a series longer than DRAWN is drawn ('' if none)."""
    if longest <= DRAWN:
        return ''
    return (f'\n{longest} points in the longest series: each series drawn as the least and '
            f'the greatest of each of {DRAWN // 2} spans (RMS over every point)')
