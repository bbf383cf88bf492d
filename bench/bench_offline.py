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
Offline replay and bag reading, against the raw read-and-deserialize rate of the same bag.

    python bench/bench_offline.py                 # bags/owc_ge_1khz, 5 repeats
    python bench/bench_offline.py --repeats 1 --bag bags/owc_cai_td_1hz   # a quick look
    python bench/bench_offline.py --profile       # and where replay's time goes (cProfile)

Cases, run in turn within each repeat (alternated, so that a busy spell of the shared
machine hits them all), every one over the whole bag:

- read (old): the reader of an earlier revision (bench/legacy_reader.py, its own MCAP walk);
- read: the package's reader (the mcap package's StreamReader, our walk inside chunks);
- read + deserialize: the reader, and rclpy's deserializer on the measurement and input
  topics: the reference of the replay goals;
- read + rosbags deserialize: the same with rosbags' deserializer (replay's fallback);
- write only: the package's BagWriter (mcap's public Writer) writing what replay writes
  (the inputs as read and, for every input, the same output messages at the same log
  times, pre-serialized), nothing read: the writer's cost;
- replay -> bag: replay_offline writing its output bag;
- replay -> bag, rosbags serializer: the same with the estimates serialized by rosbags'
  serialize_cdr (the typestore's classes, reused) instead of cdr.EstimateEncoder;
- replay -> bag, rosbags deserialize: the same with the measurements deserialized by
  rosbags instead of cdr.fixed_decoder;
- replay -> arrays: replay_arrays, the analysis mode (--npz without the file);
- replay -> bag / arrays, one sample at a time: the same with the session taking each
  measurement by itself (EstimatorSession.add, as the live node) instead of in runs
  (add_many): the replay before runs;
- replay -> arrays, rclpy / rosbags deserialize: the same with the measurements
  deserialized by rclpy (the live node's deserializer) or rosbags instead of
  cdr.fixed_decoder;
- session only: EstimatorSession.add (and add_input) over the bag's samples, already
  decoded: the filter alone; and the same in runs (add_many between the inputs).

Each case: thread CPU time per message read (min and median over the repeats) and the
wall rate (messages read / s, median).  Ratios are taken on the min CPU time per message
(the least disturbed run).  Then the serialization routes of one estimate, and the goals.
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

from legacy_reader import LegacyReader  # noqa: E402
import numpy as np  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from rosbags.rosbag2 import Reader  # noqa: E402

from tskf_ros.bag.cdr import EstimateEncoder, serialize  # noqa: E402
from tskf_ros.bag.message_types import message_class, typestore  # noqa: E402
from tskf_ros.bag.reader import BagReader, RawMessage  # noqa: E402
from tskf_ros.bag.replay import adapters, loop  # noqa: E402
from tskf_ros.bag.writer import BagWriter  # noqa: E402
from tskf_ros.messages.estimator_interface import input_from_msg, INPUT_TYPE  # noqa: E402
from tskf_ros.owc.session import EstimatorSession  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
PARAMS = REPO / 'config' / 'owc_estimator.yaml'
NS = 1_000_000_000


def quiet(line: str) -> None:
    """Log nothing."""


class LibraryEncoder:
    """EstimateEncoder's surface through rosbags: its classes (built once) and serialize_cdr."""

    def __init__(self, names: list) -> None:
        store = typestore()
        T = store.types
        self.ser = store.serialize_cdr
        n = self.n = len(names)
        dim = T['std_msgs/msg/MultiArrayDimension']
        self.msgs = {kind: T['std_msgs/msg/Float64MultiArray'](
            layout=T['std_msgs/msg/MultiArrayLayout'](
                dim=[dim(label=kind, size=n + 1, stride=(n + 1) * n),
                     dim(label=','.join(names), size=n, stride=n)], data_offset=3),
            data=np.zeros(3 + n + n * n)) for kind in EstimateEncoder.KINDS}

    def estimate(self, kind, stamp_ns, mu, x, P):
        n, m = self.n, self.msgs[kind]
        m.data[0], m.data[1] = divmod(int(stamp_ns), NS)
        m.data[2] = mu
        m.data[3:3 + n] = np.asarray(x, dtype=float).reshape(n)
        m.data[3 + n:] = np.asarray(P, dtype=float).reshape(n * n)
        return bytes(self.ser(m, 'std_msgs/msg/Float64MultiArray'))


class Swapped:
    """Replace an attribute for the duration of a case (the alternative routes)."""

    def __init__(self, owner, name, value):
        self.owner, self.name, self.value = owner, name, value

    def __enter__(self):
        self.old = getattr(self.owner, self.name)
        setattr(self.owner, self.name, self.value)

    def __exit__(self, *exc):
        setattr(self.owner, self.name, self.old)


def rclpy_sample_reader(msgtype, extract):
    """Return the measurement reader through rclpy's deserializer (the live node's)."""
    cls = message_class(msgtype)
    return lambda data, log_ns: extract(deserialize_message(data, cls), log_ns)


def rosbags_sample_reader(msgtype, extract):
    """Return the measurement reader through rosbags alone (cdr.fixed_decoder's fallback)."""
    des = typestore().deserialize_cdr
    return lambda data, log_ns: extract(des(data, msgtype), log_ns)


def read_only(cls):
    def run(ctx):
        n = 0
        for _ in cls(ctx['bag']).messages():
            n += 1
        return n
    return run


def read_deserialize(decoders):
    """Read every message; deserialize the measurement and input topics (as replay does)."""
    def run(ctx):
        n = 0
        todo = ctx[decoders]
        for raw in BagReader(ctx['bag']).messages():
            n += 1
            decode = todo.get(raw.topic)
            if decode is not None:
                decode(raw.data)
        return n
    return run


def rosbags_read_deserialize(ctx):
    """Read with rosbags alone: its Reader over every message, deserialized by its typestore."""
    des = typestore().deserialize_cdr
    n = 0
    with Reader(ctx['bag']) as reader:
        for conn, _, data in reader.messages():
            des(data, conn.msgtype)
            n += 1
    return n


def write_only(ctx):
    """Write what replay writes, pre-serialized, through BagWriter (see the module doc)."""
    _, est, _ = loop.prepare(ctx['bag'], ctx['params'], None, 'estimator', None, quiet)
    with BagWriter(ctx['tmp'] / 'written', overwrite=True) as writer:
        loop.add_topics(writer, BagReader(ctx['bag']), est, True, quiet)
        write = writer.write
        for topic, log_ns, data in ctx['writes']:
            write(topic, log_ns, data)
    return ctx['count']


def replay_bag(ctx):
    res = loop.replay(ctx['bag'], ctx['tmp'] / 'replayed', params_file=ctx['params'],
                      overwrite=True)
    return res.read


def replay_bag_library(ctx):
    with Swapped(adapters, 'EstimateEncoder', LibraryEncoder):
        return replay_bag(ctx)


def replay_arrays(ctx):
    loop.replay_arrays(ctx['bag'], ctx['params'])
    return ctx['count']


def replay_arrays_one_by_one(ctx):
    with Swapped(adapters.OfflineEstimator, 'batched', False):
        return replay_arrays(ctx)


def replay_bag_one_by_one(ctx):
    with Swapped(adapters.OfflineEstimator, 'batched', False):
        return replay_bag(ctx)


def replay_arrays_rclpy(ctx):
    with Swapped(adapters, 'sample_reader', rclpy_sample_reader):
        return replay_arrays(ctx)


def replay_arrays_rosbags(ctx):
    with Swapped(adapters, 'sample_reader', rosbags_sample_reader):
        return replay_arrays(ctx)


def replay_bag_rosbags(ctx):
    with Swapped(adapters, 'sample_reader', rosbags_sample_reader):
        return replay_bag(ctx)


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


def session_runs(ctx):
    """Run the filter alone in runs: add_many over the decoded samples between inputs."""
    session = EstimatorSession(ctx['config'].session)
    for kind, args in ctx['runs']:
        if kind:
            session.add_input(*args)
        else:
            session.add_many(*args)
    return ctx['count']


CASES = [('rosbags read + deserialize', rosbags_read_deserialize),
         ('read (old)', read_only(LegacyReader)),
         ('read', read_only(BagReader)),
         ('read + deserialize', read_deserialize('rclpy')),
         ('read + rosbags deserialize', read_deserialize('rosbags')),
         ('write only', write_only),
         ('replay -> bag', replay_bag),
         ('replay -> bag, rosbags serializer', replay_bag_library),
         ('replay -> bag, rosbags deserialize', replay_bag_rosbags),
         ('replay -> bag, one sample at a time', replay_bag_one_by_one),
         ('replay -> arrays', replay_arrays),
         ('replay -> arrays, one sample at a time', replay_arrays_one_by_one),
         ('replay -> arrays, rclpy deserialize', replay_arrays_rclpy),
         ('replay -> arrays, rosbags deserialize', replay_arrays_rosbags),
         ('session only', session_only),
         ('session only, in runs (add_many)', session_runs)]


def context(bag: Path, tmp: Path, params: Path = PARAMS) -> dict:
    """Everything the cases need, prepared untimed: the writes, the decoded samples."""
    reader, est, result = loop.prepare(bag, params, None, 'estimator', None, quiet)
    store = typestore()
    types = {result.topic: result.msgtype}
    if result.input_topic:
        types[result.input_topic] = INPUT_TYPE
    rclpy_decoders = {t: (lambda d, c=message_class(m): deserialize_message(d, c))
                      for t, m in types.items()}
    rosbags_decoders = {t: (lambda d, m=m: store.deserialize_cdr(d, m))
                        for t, m in types.items()}
    memory = loop.replay(bag, None, params_file=params)
    writes, encoded = [], {}
    for topic, log_ns, item in memory.outputs:
        if isinstance(item, RawMessage):
            writes.append((topic, log_ns, item.data))
        else:
            writes.append((topic, log_ns, encoded.setdefault(topic, serialize(item))))
    samples = []
    for raw in BagReader(bag).messages():
        if raw.topic == result.topic:
            msg = deserialize_message(raw.data, message_class(result.msgtype))
            samples.append((0, est.extract(msg, raw.log_time_ns), raw.log_time_ns))
        elif raw.topic == result.input_topic:
            msg = deserialize_message(raw.data, message_class(INPUT_TYPE))
            samples.append((1, input_from_msg(msg, est.session), raw.log_time_ns))
    runs, stretch = [], []
    for kind, args, log_ns in samples + [(1, None, 0)]:
        if kind == 0:
            stretch.append((*args, log_ns))
            continue
        if stretch:
            runs.append((0, tuple(np.array(c, dtype=d) for c, d in zip(
                zip(*stretch), (np.int64, float, float, np.int64)))))
            stretch = []
        if args is not None:
            runs.append((1, args))
    return {'bag': bag, 'tmp': tmp, 'params': params, 'rclpy': rclpy_decoders,
            'rosbags': rosbags_decoders,
            'writes': writes, 'samples': samples, 'runs': runs, 'count': memory.read,
            'config': est.config,
            'written': sum(memory.written.values()), 'n_samples': memory.samples}


def measure(ctxs: list, repeats: int, cases: list) -> list:
    """
    Run every case on every bag `repeats` times, interleaved (repeat, bag, case).

    Return, per bag, {name: [(cpu s, wall s, n)]}.
    """
    runs = [{name: [] for name, _ in cases} for _ in ctxs]
    for _ in range(repeats):
        for ctx, got in zip(ctxs, runs):
            for name, case in cases:
                c0, w0 = time.thread_time(), time.perf_counter()
                n = case(ctx)
                got[name].append((time.thread_time() - c0, time.perf_counter() - w0, n))
    return runs


def serialization_routes(repeats: int, count: int = 5000) -> dict:
    """Return {route: min us} for one step's two estimates (n = 1): corrected, predicted."""
    t = 1_700_000_000_123_456_789
    x, P = np.array([0.25]), np.array([[1e-4]])
    routes = {'fixed layout (cdr.EstimateEncoder)': EstimateEncoder(['theta']),
              "rosbags' classes (reused) + serialize_cdr": LibraryEncoder(['theta'])}
    best = {name: float('inf') for name in routes}
    for _ in range(repeats):
        for name, enc in routes.items():
            c0 = time.thread_time()
            for _ in range(count):
                enc.estimate('corrected', t, 5e-6, x, P)
                enc.estimate('predicted', t + 5000, 5e-6, x, P)
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
    wanted = [('runs.py', 'add_many', 'session.add_many (the filter, in runs)'),
              ('session.py', 'add', 'session.add (the samples a run stops at)'),
              ('adapters.py', 'encoded', 'encoding the outputs (EstimateEncoder)'),
              ('adapters.py', 'diagnostics_due', '/diagnostics (build + serialize)'),
              ('writer.py', 'write', 'BagWriter.write (mcap Writer.add_message)'),
              ('writer.py', 'add_message', "  of which mcap's Writer.add_message"),
              ('reader.py', 'messages', 'BagReader.messages (read)'),
              ('adapters.py', 'read', 'deserializing the measurements')]
    shares = {}
    for (file, _, name), (_, _, _, ct, _) in stats.stats.items():
        for suffix, func, label in wanted:
            if file.endswith(suffix) and name == func:
                shares[label] = max(shares.get(label, 0.0), ct)
    for label, ct in shares.items():
        print(f'  {label:44s} {ct:7.2f} s  {ct / total:6.1%}')
    stats.sort_stats('tottime').print_stats(12)


def report(runs: dict, ctx: dict, serial: dict) -> None:
    """Print the table and the goals of one bag."""
    count = ctx['count']
    print(f"\n{ctx['bag']}: {count:,} messages, {ctx['n_samples']:,} samples; replay "
          f"writes {ctx['written']:,} output messages besides the {count:,} inputs")
    print(f"{'case':40s} {'CPU us/msg min':>15s} {'median':>8s} {'wall msgs/s':>12s}")
    cpu, med = {}, {}
    for name, rows in runs.items():
        per = [c / n * 1e6 for c, _, n in rows]
        walls = [n / w for _, w, n in rows]
        cpu[name], med[name] = min(per), statistics.median(per)
        print(f'{name:40s} {min(per):15.2f} {med[name]:8.2f} '
              f'{statistics.median(walls):12,.0f}')
    if serial:
        print("\nserialization of one step's two estimates (Float64MultiArray), min CPU us:")
        for name, us in serial.items():
            print(f'  {name:48s} {us:7.2f}')
    rosbags, ours = 'rosbags read + deserialize', 'read + deserialize'
    goals = [
        ('replay -> arrays / rosbags read + deserialize (>= 0.7)', 'replay -> arrays',
         rosbags, 0.7),
        ('replay -> bag / rosbags read + deserialize', 'replay -> bag', rosbags, None),
        ('replay -> bag / read + deserialize (>= 0.2)', 'replay -> bag', ours, 0.2),
        ('  the same with rosbags serializing the estimates (no EstimateEncoder)',
         'replay -> bag, rosbags serializer', ours, None),
        ('  the same with rosbags deserializing the measurements (no fixed_decoder)',
         'replay -> bag, rosbags deserialize', ours, None),
        ('  the same, the session taking one sample at a time (add)',
         'replay -> bag, one sample at a time', ours, None),
        ('replay -> arrays / read + deserialize', 'replay -> arrays', ours, None),
        ('  the same, the session taking one sample at a time (add)',
         'replay -> arrays, one sample at a time', ours, None),
        ('  the same with rosbags deserializing the measurements (no fixed_decoder)',
         'replay -> arrays, rosbags deserialize', ours, None),
        ('  the same with rclpy deserializing the measurements',
         'replay -> arrays, rclpy deserialize', ours, None),
        ('read + deserialize / rosbags read + deserialize', ours, rosbags, None),
        ('  read / read (old)', 'read', 'read (old)', None),
        ("  the writer's share of replay -> bag (write only / replay -> bag)",
         'replay -> bag', 'write only', None),
        ("  the session's share of replay -> arrays", 'replay -> arrays',
         'session only, in runs (add_many)', None),
        ('  session: add one at a time / add_many in runs (times faster)',
         'session only, in runs (add_many)', 'session only', None),
    ]
    print('\ngoals: rate ratios (reference CPU per message / case CPU per message), '
          'on the min and on the median over the repeats')
    for text, case, base, goal in goals:
        if case not in cpu or base not in cpu:
            continue
        value, middle = cpu[base] / cpu[case], med[base] / med[case]
        verdict = '' if goal is None else ('  met' if middle >= goal else '  NOT met')
        print(f'  {text:76s} {value:7.3f} {middle:7.3f}{verdict}')
    if serial:
        faster = (serial["rosbags' classes (reused) + serialize_cdr"]
                  / serial['fixed layout (cdr.EstimateEncoder)'])
        print(f"  {'EstimateEncoder vs rosbags serialize_cdr (times faster)':76s} {faster:7.3f}")


SYNTHETIC_PARAMS = """/**:
  ros__parameters:
    period: 0.001
"""
# the stamps of the --synthetic bags: name -> jitter (ns, +-), uniform
JITTERS = {'exact': 0, 'jitter 1 % of the period': 10_000, 'jitter 50 us': 50_000}


def main() -> None:
    """Run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--bag', type=Path, nargs='+', default=[REPO / 'bags' / 'owc_ge_1khz'],
                        help='bags to run (interleaved within each repeat)')
    parser.add_argument('--synthetic', type=int, metavar='N',
                        help='instead: three bags of N Illuminance messages at 1 kHz, stamps '
                        'exact, jittered +-1 %% of the period and +-50 us (the node defaults, '
                        'period 1 ms)')
    parser.add_argument('--cases', nargs='+', metavar='NAME',
                        help='only these cases (names as printed; default all)')
    parser.add_argument('--repeats', type=int, default=5)
    parser.add_argument('--profile', action='store_true',
                        help='also profile one replay -> bag with cProfile')
    args = parser.parse_args()
    print(f'{platform.node()}: {platform.processor() or platform.machine()}, '
          f'{os.cpu_count()} CPUs, Python {platform.python_version()}, '
          f'{args.repeats} repeats; load average {os.getloadavg()[0]:.2f}', flush=True)
    cases = [c for c in CASES if args.cases is None or c[0] in args.cases]
    tmp = Path(tempfile.mkdtemp(prefix='bench_offline_'))
    try:
        bags, params = args.bag, PARAMS
        if args.synthetic:
            from bench_replay_memory import make_bag
            params = tmp / 'params.yaml'
            params.write_text(SYNTHETIC_PARAMS)
            bags = []
            for name, jitter in JITTERS.items():
                bags.append(tmp / name.replace(' ', '_').replace('%', 'pct'))
                make_bag(bags[-1], args.synthetic, jitter_ns=jitter)
        ctxs = []
        for k, bag in enumerate(bags):
            (tmp / str(k)).mkdir()
            ctxs.append(context(bag, tmp / str(k), params))
        runs = measure(ctxs, args.repeats, cases)
        serial = serialization_routes(args.repeats) if args.cases is None else {}
        for ctx, got in zip(ctxs, runs):
            report(got, ctx, serial)
        print(f'load average at the end {os.getloadavg()[0]:.2f}')
        if args.profile:
            profile(ctxs[0])
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == '__main__':
    main()
