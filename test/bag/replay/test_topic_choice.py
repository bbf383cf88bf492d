"""The fixed-layout decoder of replay_offline's measurements, against rclpy and rosbags."""

from pathlib import Path
import struct

from hypothesis import given, settings, strategies as st
import pytest
from rclpy.serialization import deserialize_message, serialize_message

from tskf_ros.bag import offline_replay
from tskf_ros.bag.cdr import fixed_decoder, fixed_fields, to_store
from tskf_ros.bag.message_types import message_class, typestore
from tskf_ros.bag.offline_replay import DESERIALIZE_ERRORS, sample_reader
from tskf_ros.bag.reader import BagReader, EXIT_DAMAGED
from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages.estimator_interface import extractor, INPUT_TYPES

REPO = Path(__file__).resolve().parent.parent
BAGS = REPO / 'bags'
NS = 1_000_000_000
# the float width of each struct code the decoder may read
WIDTH = {'d': 64, 'f': 32}
INT_RANGE = {'B': (0, 255), 'b': (-128, 127), 'i': (-2 ** 31, 2 ** 31 - 1)}


def slow_route(msgtype):
    """Return what replay did before: rclpy's deserializer, then the extractor."""
    cls, extract = message_class(msgtype), extractor(msgtype)
    return lambda data, log_ns: extract(deserialize_message(data, cls), log_ns)


def outcome(read, data, log_ns=123):
    """Return ('ok', the sample with its floats as bit patterns) or ('error',)."""
    try:
        stamp, value, variance = read(data, log_ns)
    except DESERIALIZE_ERRORS:
        return ('error',)
    return ('ok', stamp, struct.pack('<dd', value, variance))


@st.composite
def messages(draw, msgtype):
    """Draw an rclpy message of msgtype with any field values (NaN, inf, any frame_id)."""
    msg = message_class(msgtype)()
    stamped, layout = fixed_fields(msgtype)
    if stamped:
        msg.header.stamp.sec = draw(st.integers(-2 ** 31, 2 ** 31 - 1))
        msg.header.stamp.nanosec = draw(st.integers(0, 2 ** 32 - 1))
        msg.header.frame_id = draw(st.text(st.characters(blacklist_categories=('Cs',)),
                                           max_size=20))
    for path, code in layout:
        if code in WIDTH:
            value = draw(st.floats(width=WIDTH[code]))
        else:
            value = draw(st.integers(*INT_RANGE[code]))
        setattr(msg, path, value)
    return msg


def canonical(msg, msgtype, little_endian=True):
    """Return the rosbags typestore's canonical CDR of an rclpy message."""
    return bytes(typestore().serialize_cdr(to_store(msg), msgtype,
                                           little_endian=little_endian))


@pytest.mark.parametrize('msgtype', list(INPUT_TYPES))
@settings(max_examples=60, deadline=None)
@given(data=st.data(), log_ns=st.integers(0, 2 ** 63 - 1))
def test_the_decoder_reads_what_rclpy_and_rosbags_read(msgtype, data, log_ns):
    """Padded (rclpy), canonical (rosbags) and big-endian forms: the same sample."""
    msg = data.draw(messages(msgtype))
    fast, slow = sample_reader(msgtype, message_class(msgtype), extractor(msgtype)), \
        slow_route(msgtype)
    forms = {'padded': serialize_message(msg), 'canonical': canonical(msg, msgtype),
             'big endian': canonical(msg, msgtype, little_endian=False)}
    kind = INPUT_TYPES[msgtype]
    store_msg = typestore().deserialize_cdr(forms['canonical'], msgtype)
    want_stamp = (store_msg.header.stamp.sec * NS + store_msg.header.stamp.nanosec
                  if kind.stamped else log_ns)
    want = ('ok', want_stamp, struct.pack(
        '<dd', getattr(store_msg, kind.value),
        getattr(store_msg, kind.variance) if kind.variance else 0.0))
    for form, raw in forms.items():
        assert outcome(fast, raw, log_ns) == outcome(slow, raw, log_ns) == want, form
    decode = fixed_decoder(msgtype, [kind.value])
    assert decode(forms['big endian']) is None      # rclpy's, not ours
    assert decode(forms['padded']) is not None


@st.composite
def damaged(draw):
    """Draw a serialized measurement, cut, spliced with garbage, or with bytes overwritten."""
    msgtype = draw(st.sampled_from(sorted(INPUT_TYPES)))
    raw = bytearray(draw(st.sampled_from([serialize_message, lambda m: canonical(m, msgtype)]))(
        draw(messages(msgtype))))
    how = draw(st.sampled_from(['cut', 'overwrite', 'length', 'header', 'append', 'random']))
    if how == 'cut':
        raw = raw[:draw(st.integers(0, len(raw)))]
    elif how == 'overwrite':
        for _ in range(draw(st.integers(1, 4))):
            raw[draw(st.integers(0, len(raw) - 1))] = draw(st.integers(0, 255))
    elif how == 'length' and len(raw) >= 16:        # the frame_id's length field
        raw[12:16] = struct.pack('<I', draw(st.integers(0, 2 ** 32 - 1)))
    elif how == 'header':
        raw[:4] = draw(st.binary(min_size=4, max_size=4))
    elif how == 'append':
        raw += draw(st.binary(max_size=12))
    else:
        raw = bytearray(draw(st.binary(max_size=64)))
    return msgtype, bytes(raw)


@settings(max_examples=400, deadline=None)
@given(case=damaged())
def test_damaged_bytes_give_the_outcome_rclpy_gives(case):
    """Values where rclpy gives values (the same), an error where rclpy refuses them."""
    msgtype, raw = case
    fast = sample_reader(msgtype, message_class(msgtype), extractor(msgtype))
    assert outcome(fast, raw) == outcome(slow_route(msgtype), raw)


@pytest.mark.parametrize('name', ['owc_cai_td_1hz', 'owc_ge_1khz', 'led_alignment', 'drogue'])
def test_every_measurement_of_the_sample_bags_decodes_as_rclpy_decodes(name):
    reader = BagReader(BAGS / name)
    routes = {t: (sample_reader(i.msgtype, message_class(i.msgtype), extractor(i.msgtype)),
                  slow_route(i.msgtype))
              for t, i in reader.topics.items() if i.msgtype in INPUT_TYPES}
    assert routes, name
    seen = 0
    for raw in reader.messages():
        if raw.topic in routes:
            fast, slow = routes[raw.topic]
            got = outcome(fast, raw.data, raw.log_time_ns)
            assert got[0] == 'ok' and got == outcome(slow, raw.data, raw.log_time_ns)
            seen += 1
    assert seen > 0


def test_an_undecodable_measurement_is_damage_with_one_line(tmp_path, capsys):
    """A cut message stops the replay: what came before is written, exit 3, one line."""
    good = serialize_message(message_class('sensor_msgs/msg/Illuminance')(illuminance=1.0))
    with BagWriter(tmp_path / 'bag') as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        for k in range(5):
            w.write('/received_power', (k + 1) * NS, good if k != 3 else good[:20])
    code = offline_replay.main([str(tmp_path / 'bag'), str(tmp_path / 'est'), '-q'])
    err = capsys.readouterr().err
    assert code == EXIT_DAMAGED
    assert err.count('\n') == 1 and 'message 4 on /received_power does not deserialize' in err
    counts = {}
    for m in BagReader(tmp_path / 'est').messages():
        counts[m.topic] = counts.get(m.topic, 0) + 1
    assert counts['/received_power'] == 4      # copied as read, the cut one included
    arrays = offline_replay.replay_arrays(tmp_path / 'bag')
    assert len(arrays['sample.log_ns']) == 3
    assert 'does not deserialize' in str(arrays['meta.damage'])
