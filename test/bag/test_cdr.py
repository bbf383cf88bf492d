"""Canonical CDR: what the package writes, every library reads; both forms are read."""

from pathlib import Path
import shutil
import struct

from hypothesis import given, settings, strategies as st
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.rosbag2 import Reader
from sensor_msgs.msg import JointState
from test_bag_samples import flatten

from tskf_ros.bag import offline_replay
from tskf_ros.bag.cdr import EstimateEncoder, serialize, type_name
from tskf_ros.bag.message_types import message_class, typestore
from tskf_ros.bag.reader import BagReader, EXIT_DAMAGED, MetadataError, RawMessage
from tskf_ros.bag.writer import BagWriter
from tskf_ros.messages import conversions
from tskf_ros.tools import plot_bag

import yaml

REPO = Path(__file__).resolve().parent.parent
BAGS = REPO / 'bags'
SAMPLES = ('owc_cai_td_1hz', 'owc_ge_1khz', 'led_alignment', 'drogue')
PARAMS = REPO / 'config' / 'owc_estimator.yaml'
NS = 1_000_000_000
T0 = 1_700_000_000 * NS


def mcap_file(bag):
    return next(Path(bag).glob('*.mcap'))


@pytest.mark.parametrize('name', SAMPLES)
def test_every_sample_message_is_canonical_for_rosbags_mcap_ros2_and_rclpy(name):
    """
    Every library decodes every message to the same values: rosbags (strict), mcap_ros2, rclpy.

    Re-serializing a decoded message gives back its bytes exactly (the canonical form).
    """
    store = typestore()
    ours = list(BagReader(BAGS / name).messages())
    with Reader(BAGS / name) as reader:
        theirs = [(c.topic, t, bytes(d)) for c, t, d in reader.messages()]
    assert sorted((m.topic, m.log_time_ns, m.data) for m in ours) == sorted(theirs)
    with mcap_file(BAGS / name).open('rb') as f:
        decoded = [(ch.topic, m.log_time, d) for _, ch, m, d in
                   make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    assert len(decoded) == len(ours)
    step = max(1, len(ours) // 3000)     # all four bags, a few thousand messages each
    for k in range(0, len(ours), step):
        raw = ours[k]
        by_rosbags = store.deserialize_cdr(raw.data, raw.msgtype)
        by_rclpy = deserialize_message(raw.data, message_class(raw.msgtype))
        want = flatten(by_rclpy)
        assert flatten(by_rosbags) == want, f'{name} message {k}'
        assert decoded[k][:2] == (raw.topic, raw.log_time_ns)
        assert flatten(decoded[k][2]) == want, f'{name} message {k} (mcap_ros2)'
        assert serialize(by_rclpy) == raw.data, f'{name} message {k} is not canonical'
    for raw in ours:     # all of them, strictly: rosbags refuses trailing or missing bytes
        store.deserialize_cdr(raw.data, raw.msgtype)


def test_the_same_message_gives_the_same_bytes():
    msg = conversions.angle_to_msg(T0 + 123, [0.25], ['theta'])
    first = serialize(msg)
    assert all(serialize(msg) == first for _ in range(20))
    # the canonical size, by hand: header (4 + 4 + 4 + 1, padded to 16), name[] (4 + 4 + 6,
    # padded to 16), position[] (4, padded to 8, + 8), velocity[] (4), effort[] (4)
    assert len(first) == 4 + 16 + 16 + 4 + 4 + 8 + 4 + 4 == 60
    padded = serialize_message(msg)          # Fast-CDR: 8 bytes of trailing padding, and
    assert len(padded) == 68                 # its padding bytes are left uninitialised
    assert deserialize_message(padded, JointState) == deserialize_message(first, JointState)


def padded_and_canonical_bags(tmp_path):
    """Write the same messages in two bags: rclpy's padded Fast-CDR bytes, canonical ones."""
    bags = {}
    for form, encode in (('padded', serialize_message), ('canonical', serialize)):
        with BagWriter(tmp_path / form) as w:
            w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
            w.add_topic('/true_angle', 'sensor_msgs/msg/JointState')
            for k in range(120):
                stamp = T0 + k * NS // 10
                w.write('/true_angle', stamp, encode(
                    conversions.angle_to_msg(stamp, [0.1 * np.sin(k / 9)], ['theta'])))
                if k % 17 != 5:
                    w.write('/received_power', stamp, encode(
                        conversions.power_to_msg(stamp, 300.0 + 20.0 * np.cos(k / 7), 4.0)))
        bags[form] = tmp_path / form
    return bags


def test_every_reader_takes_both_the_padded_and_the_canonical_form(tmp_path):
    bags = padded_and_canonical_bags(tmp_path)
    raw = {form: list(BagReader(bag).messages()) for form, bag in bags.items()}
    angles = [(a, b) for a, b in zip(raw['padded'], raw['canonical'])
              if a.topic == '/true_angle']
    assert all(len(a.data) == len(b.data) + 8 for a, b in angles)     # the test means it
    with pytest.raises(Exception):     # why the package reads with rclpy, not rosbags
        typestore().deserialize_cdr(angles[0][0].data, 'sensor_msgs/msg/JointState')
    for a, b in zip(raw['padded'], raw['canonical']):       # message_types + rclpy
        cls = message_class(a.msgtype)
        assert deserialize_message(a.data, cls) == deserialize_message(b.data, cls)
    outputs = {}
    for form, bag in bags.items():       # offline replay, in memory, to a bag and to arrays
        res = offline_replay.replay(bag, None, params_file=PARAMS, diagnostics=False)
        outputs[form] = [(t, n, m) for t, n, m in res.outputs if t.startswith('/estimate')]
        assert offline_replay.main([str(bag), str(tmp_path / f'{form}_est'), '-q',
                                    '--params-file', str(PARAMS)]) == 0
        arrays = offline_replay.replay_arrays(bag, PARAMS)
        outputs[form + ' arrays'] = arrays['estimate/corrected.x'].tolist()
        assert plot_bag.main([str(bag), '--out', str(tmp_path / f'{form}_png')]) == 0
    assert outputs['padded'] == outputs['canonical'] and outputs['padded']
    assert outputs['padded arrays'] == outputs['canonical arrays']
    est = {form: [m.data for m in BagReader(tmp_path / f'{form}_est').messages()
                  if m.topic.startswith('/estimate')] for form in bags}
    assert est['padded'] == est['canonical']


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
text = st.text(st.characters(blacklist_categories=('Cs',), blacklist_characters='\0'),
               max_size=12)


@settings(max_examples=150, deadline=None)
@given(n=st.integers(1, 6), data=st.data(), frame=text,
       stamp=st.integers(0, 2 ** 31 - 10 ** 4 - 2).map(lambda s: s * NS),
       nsec=st.integers(0, NS - 1), sigma=st.integers(-10 * NS, 10 ** 4 * NS))
def test_the_fixed_layout_equals_the_library_byte_for_byte(n, data, frame, stamp, nsec,
                                                           sigma):
    """Each type EstimateEncoder writes, against rosbags' serializer of conversions' message."""
    x = np.array(data.draw(st.lists(finite, min_size=n, max_size=n)))
    P = np.array(data.draw(st.lists(finite, min_size=n * n, max_size=n * n))).reshape(n, n)
    names = data.draw(st.lists(text, min_size=n, max_size=n))
    t = stamp + nsec
    enc = EstimateEncoder(frame, names, n)
    est = conversions.estimate_to_msg(t, x, P, frame_id=frame)
    with np.errstate(invalid='ignore', over='ignore'):
        states = conversions.estimate_to_joint_state(t, x, P, names, frame_id=frame)
    jump = conversions.jump_to_msg(t, t + sigma)
    for got, msg in ((enc.estimate(t, x, P), est), (enc.states(t, x, P), states),
                     (enc.jump(t, t + sigma), jump)):
        assert got == serialize(msg), type_name(msg)
        assert deserialize_message(got, type(msg)) == msg
    assert enc.pair(t, x, P) == (serialize(est), serialize(states))


def test_the_fixed_layout_refuses_what_does_not_fit():
    with pytest.raises(ValueError):
        EstimateEncoder('', ['a'] * 7, 7)
    with pytest.raises(ValueError):
        EstimateEncoder('', ['a'], 2)


@pytest.mark.parametrize('bag, params, extra', [
    ('owc_cai_td_1hz', 'owc_estimator.yaml', []),
    ('led_alignment', 'alignment.yaml', ['--filter', 'alignment'])])
def test_a_replayed_bag_is_canonical_and_equals_the_in_memory_replay(tmp_path, bag, params,
                                                                     extra):
    bag, params = BAGS / bag, REPO / 'config' / params
    assert offline_replay.main([str(bag), str(tmp_path / 'est'), '-q',
                                '--params-file', str(params)] + extra) == 0
    memory = offline_replay.replay(bag, None, params_file=params,
                                   filter='alignment' if extra else 'estimator')
    store = typestore()
    written = list(BagReader(tmp_path / 'est').messages())
    assert [(m.topic, m.log_time_ns) for m in written] == \
        [(t, n) for t, n, _ in memory.outputs]
    for raw, (_, _, msg) in zip(written, memory.outputs):
        store.deserialize_cdr(raw.data, raw.msgtype)        # strict: canonical
        if not isinstance(msg, RawMessage):       # an output, not a copied input
            assert deserialize_message(raw.data, type(msg)) == msg
            assert raw.data == serialize(msg)
    with mcap_file(tmp_path / 'est').open('rb') as f:
        assert sum(1 for _ in make_reader(f, decoder_factories=[DecoderFactory()])
                   .iter_decoded_messages()) == len(written)


def test_replay_arrays_hold_what_the_output_bag_holds(tmp_path, capsys):
    """The arrays against the output bag decoded by rosbags, field by field."""
    bag = BAGS / 'drogue'
    params = REPO / 'config' / 'drogue_estimator.yaml'
    assert offline_replay.main([str(bag), str(tmp_path / 'est'), '-q',
                                '--params-file', str(params)]) == 0
    assert offline_replay.main([str(bag), '--npz', str(tmp_path / 'a.npz'), '-q',
                                '--params-file', str(params)]) == 0
    with np.load(tmp_path / 'a.npz') as f:
        arrays = dict(f)
    store = typestore()
    with Reader(tmp_path / 'est') as reader:
        by_topic = {}
        for conn, t, data in reader.messages():
            by_topic.setdefault(conn.topic, []).append(
                (t, store.deserialize_cdr(data, conn.msgtype)))
    for kind in ('predicted', 'corrected', 'revised/predicted', 'revised/corrected'):
        rows = by_topic.get(f'/estimate/{kind}', [])
        name = f'estimate/{kind}'
        assert arrays[f'{name}.log_ns'].tolist() == [t for t, _ in rows]
        assert arrays[f'{name}.stamp_ns'].tolist() == [
            m.header.stamp.sec * NS + m.header.stamp.nanosec for _, m in rows]
        n = arrays[f'{name}.x'].shape[1]
        for k, (_, m) in enumerate(rows):
            v = m.twist.twist
            slots = [v.linear.x, v.linear.y, v.linear.z, v.angular.x, v.angular.y, v.angular.z]
            assert arrays[f'{name}.x'][k].tolist() == slots[:n]
            assert arrays[f'{name}.P'][k].tolist() == \
                m.twist.covariance.reshape(6, 6)[:n, :n].tolist()
    mu = by_topic.get('/estimate/mu', [])
    assert arrays['estimate/mu.sigma_ns'].tolist() == [
        m.time_ref.sec * NS + m.time_ref.nanosec for _, m in mu]
    diag = by_topic['/diagnostics']
    assert arrays['diagnostics.log_ns'].tolist() == [t for t, _ in diag]
    assert arrays['diagnostics.message'].tolist() == [m.status[0].message for _, m in diag]
    power = by_topic['/received_power']
    assert arrays['sample.value'].tolist() == [m.illuminance for _, m in power]
    assert set(arrays['sample.status'].tolist()) <= {'accepted', 'inserted', 'gap',
                                                     'rejected', 'reset'}
    assert len(arrays['input.log_ns']) == len(by_topic['/input'])
    assert str(arrays['meta.damage']) == ''
    capsys.readouterr()
    assert offline_replay.main([str(bag), '--npz', str(tmp_path / 'a.npz'), '-q']) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'exists already' in err


def test_the_arrays_file_is_whole_or_absent(tmp_path, monkeypatch, capsys):
    out = tmp_path / 'a.npz'

    def fail(*args, **kwargs):
        raise OSError(28, 'No space left on device')
    monkeypatch.setattr(offline_replay.np, 'savez', fail)
    assert offline_replay.main([str(BAGS / 'owc_cai_td_1hz'), '--npz', str(out), '-q']) == 1
    assert 'No space left on device' in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(SystemExit) as info:       # --npz writes no bag: no output with it
        offline_replay.main([str(BAGS / 'owc_cai_td_1hz'), str(tmp_path / 'o'), '--npz',
                             str(out)])
    assert info.value.code == 2 and list(tmp_path.iterdir()) == []
    # a directory or an empty name is refused in one line (was: a traceback for '', and
    # DIR.npz written beside the directory)
    (tmp_path / 'd').mkdir()
    for npz in ('', str(tmp_path / 'd')):
        with pytest.raises(SystemExit) as info:
            offline_replay.main([str(BAGS / 'owc_cai_td_1hz'), '--npz', npz, '-q'])
        err = capsys.readouterr().err.strip().splitlines()
        assert info.value.code == 2 and 'a directory' in err[-1], err
    assert [p.name for p in tmp_path.iterdir()] == ['d'] and not any((tmp_path / 'd').iterdir())


def flip_in_third_chunk(src, dst):
    """Copy a bag and flip one byte in the middle of its third chunk's data."""
    shutil.copytree(src, dst)
    path = mcap_file(dst)
    data = bytearray(path.read_bytes())
    pos, chunks = 8, []
    while data[pos] != 0x0F:                 # top-level records up to DataEnd
        length = struct.unpack_from('<Q', data, pos + 1)[0]
        if data[pos] == 0x06:
            chunks.append((pos, length))
        pos += 9 + length
    assert len(chunks) >= 4
    start, length = chunks[2]
    data[start + 9 + length // 2] ^= 0x40
    path.write_bytes(bytes(data))
    return dst


def test_a_byte_flipped_in_a_sample_bag_is_damage_and_the_chunks_before_are_read(
        tmp_path, capsys):
    bag = flip_in_third_chunk(BAGS / 'owc_ge_1khz', tmp_path / 'bag')
    pristine = list(BagReader(BAGS / 'owc_ge_1khz').messages())
    reader = BagReader(bag)
    got = list(reader.messages())
    assert reader.damage is not None and 'CRC mismatch' in str(reader.damage)
    assert 0 < len(got) == reader.damage.messages_before < len(pristine)
    assert got == pristine[:len(got)]
    assert offline_replay.main([str(bag), '--npz', str(tmp_path / 'a.npz'), '-q']) == \
        EXIT_DAMAGED
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'CRC mismatch' in err
    with np.load(tmp_path / 'a.npz') as f:
        assert len(f['sample.log_ns']) == sum(m.topic == '/received_power' for m in got)
        assert 'CRC mismatch' in str(f['meta.damage'])


def test_a_storage_file_symlinked_outside_the_bag_is_refused(tmp_path):
    shutil.copytree(BAGS / 'owc_cai_td_1hz', tmp_path / 'outside')
    bag = tmp_path / 'bag'
    shutil.copytree(BAGS / 'owc_cai_td_1hz', bag)
    name = mcap_file(bag).name
    (bag / name).unlink()
    (bag / name).symlink_to(tmp_path / 'outside' / name)
    with pytest.raises(MetadataError, match='outside the bag directory') as info:
        BagReader(bag)
    assert '\n' not in str(info.value)
    meta = bag / 'metadata.yaml'
    doc = yaml.safe_load(meta.read_text())
    doc['rosbag2_bagfile_information']['relative_file_paths'] = ['../outside/' + name]
    meta.write_text(yaml.safe_dump(doc))
    assert offline_replay.main([str(bag), '--npz', str(tmp_path / 'a.npz'), '-q']) == 1
    assert not (tmp_path / 'a.npz').exists()


def test_joint_state_padding_is_what_rosbags_refuses():
    """The upstream behaviour the readers must live with (Fast-CDR trailing padding)."""
    padded = serialize_message(JointState(name=['a'], position=[1.0]))
    canonical = serialize(JointState(name=['a'], position=[1.0]))
    assert len(padded) > len(canonical)
    assert deserialize_message(padded, JointState) == deserialize_message(canonical, JointState)
