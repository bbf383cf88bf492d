"""
Offline replay throughput against the raw read-and-deserialize rate of the same bag.

    python bench/bench_offline.py                  # the 1 kHz sample and a 1e6-message bag
    python bench/bench_offline.py --million 0      # the sample only

Both rates use the same reader (tskf_ros.bag.reader, record by record) and the same
deserializer (rclpy.serialization): "read" reads every message of the bag and deserializes
the measurement topic; "replay" is replay_offline writing its output bag (filter, output
messages, serialization and writing included).  The 1,000,000-message bag (1 kHz
received power for 1000 s, Gilbert-Elliott blockages, no truth topic) is generated in
/tmp and not kept.  Sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and its own
ROS_DOMAIN_ID, although nothing here uses DDS.
"""

import argparse
import os
from pathlib import Path
import platform
import shutil
import tempfile
import time

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 101))

from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import Illuminance  # noqa: E402

from tskf_ros.bag.offline_replay import replay  # noqa: E402
from tskf_ros.bag.reader import BagReader  # noqa: E402
from tskf_ros.bag.writer import BagWriter  # noqa: E402
from tskf_ros.messages import conversions  # noqa: E402
from tskf_ros.owc.vibrating_link import OwcLink, OwcLinkConfig  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
PARAMS = REPO / 'config' / 'owc_estimator.yaml'
NS = 1_000_000_000


def read_rate(bag: Path, topic: str = '/received_power') -> tuple[int, float]:
    """Read every message and deserialize the measurement topic; return (count, seconds)."""
    t0 = time.perf_counter()
    n = 0
    for raw in BagReader(bag).messages():
        n += 1
        if raw.topic == topic:
            deserialize_message(raw.data, Illuminance)
    return n, time.perf_counter() - t0


def replay_rate(bag: Path, out: Path) -> tuple[int, float, int]:
    """Run replay_offline into `out`; return (messages read, seconds, samples)."""
    res = replay(bag, out, params_file=PARAMS, overwrite=True)
    return res.read, res.seconds, res.samples


def million_bag(path: Path, n: int) -> Path:
    """Write n received-power samples at 1 kHz through a Gilbert-Elliott channel."""
    link = OwcLink(OwcLinkConfig(rate=1000.0, seed=7, blockage='gilbert_elliott'))
    with BagWriter(path, overwrite=True, compress=True) as w:
        w.add_topic('/received_power', 'sensor_msgs/msg/Illuminance')
        written, t0 = 0, 1_700_000_000 * NS
        while written < n:
            s = link.generate(100_000)
            for i in range(len(s)):
                if written == n:
                    break
                if s.blocked[i] or not s.reading[i] > 0:
                    continue
                stamp = t0 + int(s.index[i]) * 1_000_000
                w.write('/received_power', stamp, serialize_message(
                    conversions.power_to_msg(stamp, s.reading[i], 100.0)))
                written += 1
    return path


def report(name: str, bag: Path, out: Path) -> None:
    """Print both rates and their ratio for one bag."""
    n_read, t_read = read_rate(bag)
    n_rep, t_rep, samples = replay_rate(bag, out)
    r_read, r_rep = n_read / t_read, n_rep / t_rep
    print(f'{name}: {n_read:,} messages ({samples:,} samples)')
    print(f'  read + deserialize : {r_read:12,.0f} msgs/s ({t_read:.2f} s)')
    print(f'  offline replay     : {r_rep:12,.0f} msgs/s ({t_rep:.2f} s)')
    print(f'  replay / read      : {r_rep / r_read:12.3f}  (1.0: the filter and writing '
          'would cost nothing)', flush=True)


def main() -> None:
    """Run the benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--million', type=int, default=1_000_000,
                        help='messages of the generated bag (0: skip)')
    args = parser.parse_args()
    print(f'{platform.node()}: {platform.processor() or platform.machine()}, '
          f'{os.cpu_count()} CPUs, Python {platform.python_version()}')
    tmp = Path(tempfile.mkdtemp(prefix='bench_offline_'))
    try:
        report('bags/owc_ge_1khz', REPO / 'bags' / 'owc_ge_1khz', tmp / 'ge_out')
        if args.million:
            t0 = time.perf_counter()
            bag = million_bag(tmp / 'million', args.million)
            print(f'(generated {args.million:,} messages in {time.perf_counter() - t0:.0f} s)')
            report(f'{args.million:,}-message bag', bag, tmp / 'million_out')
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == '__main__':
    main()
