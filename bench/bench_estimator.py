"""
Benchmark: the estimator node against a bare rclpy relay, and the filter step against numpy.

    python bench/bench_estimator.py [--messages 3000] [--window 20]

1. Node throughput, in one process on one SingleThreadedExecutor: a driver publishes
   stamped Illuminance messages (1 ms apart) keeping at most `window` in flight, and a
   sink counts what comes out.  Once through a bare relay (subscribe, republish, no work),
   once through TimescaleEstimator (subscribe, filter, publish predicted, corrected, mu).
2. Per-step cost of the core: TimeScaleKalmanFilter.step, EstimatorSession.add, and a
   textbook numpy Kalman step (F = I + mu A, Q_d = mu GQG^T, R_d = R / mu) on the same model.
"""

import argparse
import os
from pathlib import Path
import platform
import sys
import time
import timeit

# runnable from a source checkout without installing: the repository root on the path
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(os.getpid() % 100 + 1))

import numpy as np  # noqa: E402
import rclpy  # noqa: E402
from rclpy.context import Context  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import qos_profile_sensor_data, QoSProfile  # noqa: E402
from sensor_msgs.msg import Illuminance  # noqa: E402

from tskf_ros.core.linear_models import owc, spring_mass  # noqa: E402
from tskf_ros.messages import conversions  # noqa: E402
from tskf_ros.nodes.timescale_estimator import TimescaleEstimator  # noqa: E402
from tskf_ros.owc.estimator_session import EstimatorConfig, EstimatorSession  # noqa: E402

NS = 1_000_000_000


class Relay(Node):
    """Subscribe to measurement and republish each message unchanged."""

    def __init__(self, context: Context, copies: int = 1) -> None:
        super().__init__('relay', context=context)
        pubs = [self.create_publisher(Illuminance, 'relayed' + ('' if i == 0 else str(i)),
                                      QoSProfile(depth=100)) for i in range(copies)]

        def relay(msg: Illuminance) -> None:
            for pub in pubs:
                pub.publish(msg)
        self.create_subscription(Illuminance, 'measurement', relay,
                                 QoSProfile(depth=100,
                                            reliability=qos_profile_sensor_data.reliability))


def throughput(kind: str, messages: int, window: int) -> float:
    """Messages per second through the relay or the estimator (in one process)."""
    context = Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    driver = rclpy.create_node('driver', context=context)
    if kind.startswith('relay'):
        node, out_topic, out_type = Relay(context, 3 if kind == 'relay3' else 1), 'relayed', \
            Illuminance
    else:
        node, out_topic = TimescaleEstimator(context=context), 'estimate/predicted'
        from geometry_msgs.msg import TwistWithCovarianceStamped as out_type
    got = []
    driver.create_subscription(out_type, out_topic, lambda m: got.append(1),
                               QoSProfile(depth=1000))
    pub = driver.create_publisher(Illuminance, 'measurement', QoSProfile(depth=1000))
    executor.add_node(node)
    executor.add_node(driver)
    rng = np.random.default_rng(0)
    power = rng.normal(200.0, 10.0, messages + 1)
    try:
        while pub.get_subscription_count() < 1 or driver.count_publishers(out_topic) < 1:
            executor.spin_once(timeout_sec=0.01)
        # warm up, then time `messages` messages with at most `window` in flight
        sent = 0

        def send() -> None:
            nonlocal sent
            sent += 1
            pub.publish(conversions.power_to_msg(sent * NS // 1000, power[sent % power.size]))
        send()
        while not got:
            executor.spin_once(timeout_sec=0.01)
        got.clear()
        sent_before = sent
        start = time.perf_counter()
        while len(got) < messages:
            while sent - sent_before - len(got) < window and sent - sent_before < messages:
                send()
            executor.spin_once(timeout_sec=0.1)
            if time.perf_counter() - start > 120:
                raise TimeoutError(f'{kind}: {len(got)} of {messages} messages came back')
        return messages / (time.perf_counter() - start)
    finally:
        executor.shutdown()
        node.destroy_node()
        driver.destroy_node()
        context.try_shutdown()


def textbook_step(F, Qd, C, Rd, D, x, P, y):
    """Textbook predictive Kalman step: update with y, then predict through F."""
    S = C @ P @ C.T + Rd
    K = P @ C.T @ np.linalg.inv(S)
    x = x + K @ (y - C @ x - D)
    P = (np.eye(P.shape[0]) - K @ C) @ P
    return F @ x, F @ P @ F.T + Qd


def step_costs(repeat: int = 20000) -> list:
    """(model, filter step us, session add us, textbook step us) per model."""
    rows = []
    for model, mu, y in ((owc(), 1.0, np.array([200.0])), (spring_mass(), 0.5, np.array([0.5]))):
        kf = model.make_filter()
        t_step = min(timeit.repeat(lambda: kf.step(mu, y), number=repeat, repeat=3)) / repeat
        session = EstimatorSession(EstimatorConfig(model, nonpositive_is_gap=False))
        stamp = [NS]

        def add() -> None:
            stamp[0] += int(mu * NS)
            session.add(stamp[0], y)
        t_add = min(timeit.repeat(add, number=repeat, repeat=3)) / repeat
        n = model.A.shape[0]
        G = model.G if model.G is not None else np.eye(n)
        F, Qd = np.eye(n) + mu * model.A, mu * G @ model.Q @ G.T
        D = model.D if model.D is not None else np.zeros(1)
        state = [model.x0.copy(), model.P0.copy()]

        def textbook() -> None:
            state[:] = textbook_step(F, Qd, model.C, model.R / mu, D, *state, y)
        t_text = min(timeit.repeat(textbook, number=repeat, repeat=3)) / repeat
        rows.append((model.name, t_step * 1e6, t_add * 1e6, t_text * 1e6))
    return rows


def main() -> None:
    """Run both benchmarks and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--messages', type=int, default=3000)
    parser.add_argument('--window', type=int, default=20)
    parser.add_argument('--repeat', type=int, default=20000)
    args = parser.parse_args()
    print(f'machine: {platform.machine()}, {os.cpu_count()} CPUs, {platform.processor() or ""} '
          f'Python {platform.python_version()}, numpy {np.__version__}, '
          f'{platform.platform()}')
    relay = throughput('relay', args.messages, args.window)
    relay3 = throughput('relay3', args.messages, args.window)
    est = throughput('estimator', args.messages, args.window)
    print(f'bare relay (1 out):          {relay:8.0f} msg/s')
    print(f'bare relay (3 out per in):   {relay3:8.0f} msg/s')
    print(f'timescale_estimator (5 out): {est:8.0f} msg/s')
    print(f'ratio estimator/relay: {est / relay:.2f}; estimator/relay with 3 outputs: '
          f'{est / relay3:.2f}')
    print('per-step cost (us)      filter.step  session.add  textbook numpy KF step')
    for name, t_step, t_add, t_text in step_costs(args.repeat):
        print(f'  {name:20s} {t_step:10.1f} {t_add:12.1f} {t_text:14.1f}')


if __name__ == '__main__':
    main()
