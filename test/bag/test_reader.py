"""Property-based: a damaged bag raises only BagError or reports damage, and never hangs."""

from pathlib import Path
import shutil
import tempfile
import time

from hypothesis import given, HealthCheck, settings, strategies as st
import pytest
from rclpy.serialization import serialize_message

from tskf_ros.bag.reader import BagError, BagReader
from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages import conversions

NS = 1_000_000_000
T0 = 1_700_000_000 * NS
N = 24
# s: reading a small damaged bag must end well within this (it takes milliseconds)
BOUND = 5.0
SETTINGS = settings(derandomize=True, max_examples=60, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


def _make(path, compress):
    with BagWriter(path, compress=compress, chunk_size=400) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        w.add_topic('/other', 'sensor_msgs/msg/Illuminance')
        for k in range(N):
            stamp = T0 + k * NS
            w.write('/received_power' if k % 3 else '/other', stamp, serialize_message(
                conversions.power_to_msg(stamp, 200.0 + k, 4.0)))
    return path


@pytest.fixture(scope='module')
def pristine():
    """Return {compress: (mcap bytes, metadata.yaml text)} of two small valid bags."""
    top = Path(tempfile.mkdtemp(prefix='tskf_props_'))
    try:
        out = {}
        for compress in (False, True):
            bag = _make(top / f'b{int(compress)}', compress)
            out[compress] = ((bag / f'{bag.name}.mcap').read_bytes(),
                             (bag / 'metadata.yaml').read_text())
        yield out
    finally:
        shutil.rmtree(top)


def read_everything(path):
    """Open and read a bag; return (messages, damage), or raise BagError; time-bounded."""
    start = time.monotonic()
    reader = BagReader(path)
    msgs = [(m.topic, m.log_time_ns, m.data) for m in reader.messages()]
    assert time.monotonic() - start < BOUND
    return msgs, reader.damage


def check(path, expected):
    """
    Whatever the damage: a one-line BagError, or the original messages up to the damage.

    The messages read are always the first ones of the original bag, byte for byte (the
    chunk and data CRCs leave no silent change); fewer than all means damage is reported.
    """
    try:
        msgs, damage = read_everything(path)
    except BagError as exc:
        assert str(exc) and '\n' not in str(exc)
        return
    assert msgs == expected[:len(msgs)]
    if damage is None:
        assert len(msgs) == len(expected)
    else:
        assert damage.messages_before == len(msgs)
        assert '\n' not in str(damage)


def write_bag(tmp_path, name, mcap_bytes, meta_text):
    bag = tmp_path / name
    bag.mkdir()
    (bag / f'{name}.mcap').write_bytes(mcap_bytes)
    (bag / 'metadata.yaml').write_text(meta_text)
    return bag


def expected_messages():
    out = []
    for k in range(N):
        stamp = T0 + k * NS
        out.append(('/received_power' if k % 3 else '/other', stamp, serialize_message(
            conversions.power_to_msg(stamp, 200.0 + k, 4.0))))
    return out


flips = st.lists(st.tuples(st.integers(min_value=0), st.integers(min_value=0, max_value=7)),
                 min_size=1, max_size=4)


@SETTINGS
@given(compress=st.booleans(), flips=flips, bare=st.booleans())
def test_flipped_bits_raise_bag_error_or_report_damage(pristine, tmp_path_factory,
                                                       compress, flips, bare):
    data, meta = pristine[compress]
    damaged = bytearray(data)
    for pos, bit in flips:
        damaged[pos % len(damaged)] ^= 1 << bit
    tmp = tmp_path_factory.mktemp('flip')
    bag = write_bag(tmp, 'b', bytes(damaged), meta.replace(f'b{int(compress)}', 'b'))
    check(bag / 'b.mcap' if bare else bag, expected_messages())


@SETTINGS
@given(compress=st.booleans(), cut=st.integers(min_value=0), bare=st.booleans())
def test_truncations_keep_a_prefix(pristine, tmp_path_factory, compress, cut, bare):
    data, meta = pristine[compress]
    tmp = tmp_path_factory.mktemp('cut')
    bag = write_bag(tmp, 'b', data[:cut % (len(data) + 1)],
                    meta.replace(f'b{int(compress)}', 'b'))
    check(bag / 'b.mcap' if bare else bag, expected_messages())


@SETTINGS
@given(text=st.text(max_size=200), keep=st.integers(min_value=0))
def test_damaged_metadata_is_a_bag_error(pristine, tmp_path_factory, text, keep):
    data, meta = pristine[False]
    meta = meta.replace('b0', 'b')
    tmp = tmp_path_factory.mktemp('meta')
    bag = write_bag(tmp, 'b', data, meta[:keep % (len(meta) + 1)] + text)
    check(bag, expected_messages())
