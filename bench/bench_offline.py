"""
Offline replay and bag reading, against the raw read-and-deserialize rate of the same bag.

    python bench/bench_offline.py                 # bags/owc_ge_1khz, 5 repeats
    python bench/bench_offline.py --repeats 1 --bag bags/owc_cai_td_1hz   # a quick look
    python bench/bench_offline.py --profile       # and where replay's time goes (cProfile)

Cases, run in turn within each repeat (alternated, so that a busy spell of the shared
machine hits them all), every one over the whole bag:

- read (old): the reader before this revision (bench/legacy_reader.py, its own MCAP walk);
- read (library only): the mcap package for every record, chunks' records included;
- read: the package's reader (the mcap package, our record walk inside chunks);
- read + deserialize: the reader, and rclpy's deserializer on the measurement topic: the
  reference of the replay goals;
- read + fixed decode: the reader, and cdr.fixed_decoder (what replay uses, rclpy only for
  what it does not take) on the measurement topic;
- I/O floor: read + deserialize, plus writing a bag with the same messages replay writes
  (the inputs, and for every input the same number of output messages of the same types
  at the same log times, pre-built and pre-serialized) through the same BagWriter:
  everything replay does but the filter and building its messages;
- I/O floor (mcap Writer): the same, with the mcap package's own Writer in BagWriter (as
  before this revision: its add_message costs several times the chunk writer's);
- replay -> bag: replay_offline writing its output bag;
- replay -> arrays: replay_arrays, the analysis mode (--npz without the file);
- session only: EstimatorSession.add (and add_input) over the bag's samples, already
  decoded: the filter alone.

Each case: thread CPU time per message read (min and median over the repeats) and the
wall rate (messages read / s, median).  Ratios are taken on the min CPU time per message
(the least disturbed run).  Then the serialization routes of one estimate (the fixed
layout of tskf_ros.bag.cdr, rosbags' serializer, rclpy), and the goals with their ratios.
Sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and its own ROS_DOMAIN_ID, although nothing
here uses DDS.
"""

import argparse
import cProfile
import os
from pathlib import Path
import platform
import pstats
import shutil
import statistics
import sys
import tempfile
import time

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 101))

sys.path.insert(0, str(Path(__file__).resolve().parent))

from legacy_reader import LegacyReader, LibraryOnlyReader  # noqa: E402
from mcap.writer import Writer as McapWriter  # noqa: E402
import numpy as np  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402

from tskf_ros.bag import offline_replay  # noqa: E402
from tskf_ros.bag import writer as bag_writer  # noqa: E402
from tskf_ros.bag.cdr import EstimateEncoder, serialize  # noqa: E402
from tskf_ros.bag.message_types import message_class, typestore  # noqa: E402
from tskf_ros.bag.reader import BagReader, RawMessage  # noqa: E402
from tskf_ros.bag.writer import BagWriter  # noqa: E402
from tskf_ros.messages import conversions  # noqa: E402
from tskf_ros.messages.estimator_interface import input_from_msg, INPUT_TYPE  # noqa: E402
from tskf_ros.owc.session import EstimatorSession  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
PARAMS = REPO / 'config' / 'owc_estimator.yaml'


def read_only(cls):
    def run(ctx):
        n = 0
        for _ in cls(ctx['bag']).messages():
            n += 1
        return n
    return run


def read_deserialize(ctx):
    """Read every message; deserialize the measurement and input topics (as replay does)."""
    n = 0
    todo = ctx['decode']
    for raw in BagReader(ctx['bag']).messages():
        n += 1
        cls = todo.get(raw.topic)
        if cls is not None:
            deserialize_message(raw.data, cls)
    return n


def read_fixed_decode(ctx):
    """Read every message; decode the measurements as replay does (cdr.fixed_decoder)."""
    n = 0
    todo = ctx['fixed']
    for raw in BagReader(ctx['bag']).messages():
        n += 1
        read = todo.get(raw.topic)
        if read is not None:
            read(raw.data, raw.log_time_ns)
    return n


def io_floor_mcap(ctx):
    """Run the I/O floor with the mcap package's Writer in BagWriter (as before)."""
    fast = bag_writer._ChunkWriter
    bag_writer._ChunkWriter = McapWriter
    try:
        return io_floor(ctx)
    finally:
        bag_writer._ChunkWriter = fast


def io_floor(ctx):
    """Read + deserialize + write what replay writes, pre-built (see the module doc)."""
    todo, plan, prebuilt = ctx['decode'], ctx['plan'], ctx['prebuilt']
    reader = BagReader(ctx['bag'])
    out = ctx['tmp'] / 'floor'
    _, est, _ = offline_replay._prepare(ctx['bag'], PARAMS, None, 'estimator', None,
                                        lambda s: None)
    n = 0
    with BagWriter(out, overwrite=True) as writer:
        offline_replay._add_topics(writer, reader, est, True, lambda s: None)
        write = writer.write
        steps = iter(plan)
        for raw in reader.messages():
            n += 1
            for topic, log_ns in next(steps):
                if topic is None:
                    write(raw.topic, raw.log_time_ns, raw.data)
                    cls = todo.get(raw.topic)
                    if cls is not None:
                        deserialize_message(raw.data, cls)
                else:
                    write(topic, log_ns, prebuilt[topic])
    return n


def replay_bag(ctx):
    res = offline_replay.replay(ctx['bag'], ctx['tmp'] / 'replayed', params_file=PARAMS,
                                overwrite=True)
    return res.read


def replay_arrays(ctx):
    offline_replay.replay_arrays(ctx['bag'], PARAMS)
    return ctx['count']


def session_only(ctx):
    """Run the filter alone: session.add / add_input over the decoded samples, in order."""
    session = EstimatorSession(ctx['config'].session)
    add, add_input = session.add, session.add_input
    for kind, args, log_ns in ctx['samples']:
        if kind:
            add_input(*args)
        else:
            add(*args, now_ns=log_ns)
    return ctx['count']


CASES = [('read (old)', read_only(LegacyReader)),
         ('read (library only)', read_only(LibraryOnlyReader)),
         ('read', read_only(BagReader)),
         ('read + deserialize', read_deserialize),
         ('read + fixed decode', read_fixed_decode),
         ('I/O floor', io_floor),
         ('I/O floor (mcap Writer)', io_floor_mcap),
         ('replay -> bag', replay_bag),
         ('replay -> arrays', replay_arrays),
         ('session only', session_only)]


def context(bag: Path, tmp: Path) -> dict:
    """Everything the cases need, prepared untimed: the plan of writes, decoded samples."""
    reader, est, result = offline_replay._prepare(bag, PARAMS, None, 'estimator', None,
                                                  lambda s: None)
    decode = {result.topic: est.cls}
    fixed = {result.topic: est.read_sample}
    if result.input_topic:
        decode[result.input_topic] = message_class(INPUT_TYPE)
    memory = offline_replay.replay(bag, None, params_file=PARAMS)
    plan, step, prebuilt = [], [], {}
    for topic, log_ns, item in memory.outputs:
        if isinstance(item, RawMessage):
            step.append((None, log_ns))
            plan.append(step)
            step = []
        else:
            step.append((topic, log_ns))
            prebuilt.setdefault(topic, serialize(item))
    if step:
        plan[-1] += step
    samples = []
    for raw in BagReader(bag).messages():
        if raw.topic == result.topic:
            msg = deserialize_message(raw.data, est.cls)
            samples.append((0, est.extract(msg, raw.log_time_ns), raw.log_time_ns))
        elif raw.topic == result.input_topic:
            msg = deserialize_message(raw.data, decode[raw.topic])
            samples.append((1, input_from_msg(msg, est.session), raw.log_time_ns))
    return {'bag': bag, 'tmp': tmp, 'decode': decode, 'fixed': fixed, 'plan': plan,
            'prebuilt': prebuilt, 'samples': samples, 'count': memory.read, 'config': est.config,
            'written': sum(memory.written.values()), 'n_samples': memory.samples}


def measure(ctx: dict, repeats: int) -> dict:
    """Run every case `repeats` times, alternating; return {name: [(cpu s, wall s, n)]}."""
    runs = {name: [] for name, _ in CASES}
    for _ in range(repeats):
        for name, case in CASES:
            c0, w0 = time.thread_time(), time.perf_counter()
            n = case(ctx)
            runs[name].append((time.thread_time() - c0, time.perf_counter() - w0, n))
    return runs


def serialization_routes(repeats: int, count: int = 5000) -> dict:
    """Return {route: min us per estimate} for one estimate's two messages (n = 1)."""
    store = typestore()
    t = 1_700_000_000_123_456_789
    x, P = np.array([0.25]), np.array([[1e-4]])
    enc = EstimateEncoder('link', ['theta'], 1)
    T = store.types

    def library():       # rosbags' own message classes, built directly, and its serializer
        sec, nsec = divmod(t, 1_000_000_000)
        header = T['std_msgs/msg/Header'](stamp=T['builtin_interfaces/msg/Time'](
            sec=sec, nanosec=nsec), frame_id='link')
        cov = np.zeros(36)
        cov[0] = P[0, 0]
        v3 = T['geometry_msgs/msg/Vector3']
        twist = T['geometry_msgs/msg/TwistWithCovariance'](
            twist=T['geometry_msgs/msg/Twist'](linear=v3(x=float(x[0]), y=0.0, z=0.0),
                                               angular=v3(x=0.0, y=0.0, z=0.0)),
            covariance=cov)
        store.serialize_cdr(T['geometry_msgs/msg/TwistWithCovarianceStamped'](
            header=header, twist=twist), 'geometry_msgs/msg/TwistWithCovarianceStamped')
        store.serialize_cdr(T['sensor_msgs/msg/JointState'](
            header=header, name=['theta'], position=x.copy(),
            velocity=np.sqrt(np.maximum(np.diag(P), 0.0)), effort=np.zeros(0)),
            'sensor_msgs/msg/JointState')

    def rclpy_route():   # what replay did before: rclpy messages, Fast-CDR
        serialize_message(conversions.estimate_to_msg(t, x, P, frame_id='link'))
        serialize_message(conversions.estimate_to_joint_state(t, x, P, ['theta'],
                                                              frame_id='link'))

    def direct():
        enc.estimate(t, x, P)
        enc.states(t, x, P)

    routes = {'fixed layout (cdr.EstimateEncoder)': direct,
              "rosbags' classes + serialize_cdr": library,
              'rclpy messages + serialize_message (before)': rclpy_route}
    best = {name: float('inf') for name in routes}
    for _ in range(repeats):
        for name, fn in routes.items():
            c0 = time.thread_time()
            for _ in range(count):
                fn()
            best[name] = min(best[name], (time.thread_time() - c0) / count * 1e6)
    return best


def profile(ctx: dict) -> None:
    """Print where replay -> bag spends its time (cProfile, cumulative, top functions)."""
    prof = cProfile.Profile()
    prof.enable()
    replay_bag(ctx)
    prof.disable()
    stats = pstats.Stats(prof)
    total = stats.total_tt
    print(f'\nprofile of replay -> bag ({total:.1f} s under cProfile): cumulative share')
    wanted = [('owc/session/session.py', 'add', 'session.add (the filter)'),
              ('offline_replay.py', 'encoded', 'encoding the outputs (fixed layout)'),
              ('offline_replay.py', 'diagnostics_due', '/diagnostics (build + serialize)'),
              ('writer.py', 'write', 'BagWriter.write (chunk writer)'),
              ('reader.py', 'messages', 'BagReader.messages (read)'),
              ('offline_replay.py', 'read', 'decoding the measurements (fixed layout)'),
              ('~', '<built-in method rclpy._rclpy_pybind11.rclpy_deserialize>',
               'rclpy deserialize')]
    shares = {}
    for (file, _, name), (_, _, _, ct, _) in stats.stats.items():
        for suffix, func, label in wanted:
            if file.endswith(suffix) and name == func:
                shares[label] = max(shares.get(label, 0.0), ct)
    for label, ct in shares.items():
        print(f'  {label:40s} {ct:7.2f} s  {ct / total:6.1%}')
    stats.sort_stats('tottime').print_stats(12)


def report(runs: dict, ctx: dict, serial: dict) -> None:
    """Print the table and the goals."""
    count = ctx['count']
    print(f"{ctx['bag']}: {count:,} messages, {ctx['n_samples']:,} samples; replay "
          f"writes {ctx['written']:,} output messages besides the {count:,} inputs")
    print(f"{'case':24s} {'CPU us/msg min':>15s} {'median':>8s} {'wall msgs/s':>12s}")
    cpu = {}
    for name, rows in runs.items():
        per = [c / n * 1e6 for c, _, n in rows]
        walls = [n / w for _, w, n in rows]
        cpu[name] = min(per)
        print(f'{name:24s} {min(per):15.2f} {statistics.median(per):8.2f} '
              f'{statistics.median(walls):12,.0f}')
    ref = cpu['read + deserialize']

    def ratio(name, base=ref):
        return base / cpu[name]
    print('\nserialization of one estimate (TwistWithCovarianceStamped + JointState), '
          'min CPU us:')
    for name, us in serial.items():
        print(f'  {name:48s} {us:7.2f}')
    fixed = serial['fixed layout (cdr.EstimateEncoder)']
    lib = serial["rosbags' classes + serialize_cdr"]
    session = cpu['session only']
    goals = [
        ('issue 12: read through the library vs the old reader (>= 1.0)',
         ratio('read', cpu['read (old)']), 1.0),
        ('  (library only, chunks included, vs the old reader)',
         ratio('read (library only)', cpu['read (old)']), None),
        ('issue 13.4: replay -> bag / read + deserialize (>= 0.25)', ratio('replay -> bag'),
         0.25),
        ('  I/O floor / read + deserialize (its ceiling)', ratio('I/O floor'), None),
        ('  I/O floor, mcap Writer / read + deserialize (the ceiling before)',
         ratio('I/O floor (mcap Writer)'), None),
        ('  read + fixed decode / read + deserialize', ratio('read + fixed decode'), None),
        ('issue 13.4: replay -> arrays / read + deserialize (>= 0.8)',
         ratio('replay -> arrays'), 0.8),
        ('issue 13.4: fixed layout vs library serialization (>= 2x to keep it)',
         lib / fixed, 2.0),
        ("  the session's share of replay -> bag's CPU", session / cpu['replay -> bag'], None),
        ("  the session's share of replay -> arrays' CPU",
         session / cpu['replay -> arrays'], None),
        ('  replay -> arrays without the session / read + deserialize',
         ref / (cpu['replay -> arrays'] - session), None),
    ]
    print('\ngoals (ratios on min CPU per message):')
    for text, value, goal in goals:
        verdict = '' if goal is None else ('  met' if value >= goal else '  NOT met')
        print(f'  {text:70s} {value:7.3f}{verdict}')


def main() -> None:
    """Run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--bag', type=Path, default=REPO / 'bags' / 'owc_ge_1khz')
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--profile', action='store_true',
                        help='also profile one replay -> bag with cProfile')
    args = parser.parse_args()
    print(f'{platform.node()}: {platform.processor() or platform.machine()}, '
          f'{os.cpu_count()} CPUs, Python {platform.python_version()}, '
          f'{args.repeats} repeats', flush=True)
    tmp = Path(tempfile.mkdtemp(prefix='bench_offline_'))
    try:
        ctx = context(args.bag, tmp)
        runs = measure(ctx, args.repeats)
        serial = serialization_routes(args.repeats)
        report(runs, ctx, serial)
        if args.profile:
            profile(ctx)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == '__main__':
    main()
