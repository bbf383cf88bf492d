"""The power_meter_simulator node: the intermittent OWC link of Cai et al. IV-A/B."""

from dataclasses import dataclass, replace
from typing import Optional

from rcl_interfaces.msg import ParameterDescriptor, ParameterType, SetParametersResult

from tskf_ros.core.units import NS
from tskf_ros.messages import conversions
from tskf_ros.messages.estimator_interface import POWER_TOPIC
from tskf_ros.messages.parameters import BLOCKAGE_HELP, descriptor
from tskf_ros.nodes.node_base import (config_from_parameters, declare_config_fields,
                                      LinkSimulatorNode, MAX_BATCH, run_node)
from tskf_ros.owc.vibrating_link import OwcLink, OwcLinkConfig, OwcLinkError, Samples

NODE_NAME = 'power_meter_simulator'

LINK_HELP = {
    'rate': ('samples per second (Cai IV-C: 1 Hz; 1 kHz works)', (1e-3, 10_000.0)),
    'seed': ('seed of every random stream: same parameters and seed, same samples', None),
    'vibration_frequency': ('Hz of the random vibration signal (Cai IV-A: 2 Hz)',
                            (0.0, 1000.0)),
    'phase_diffusion': ('rad^2/s: phase noise that makes the 2 Hz signal random',
                        (0.0, 1e4)),
    'rest_angle': ('rad: relative angle with the table at rest (0.4141: start of eq. (2))',
                   (-1.6, 1.6)),
    'knob_min': ('rad: smallest vibration amplitude the gain knob gives', (0.0, 3.0)),
    'knob_max': ('rad: largest vibration amplitude the gain knob gives', (0.0, 3.0)),
    'knob_initial': ('rad: vibration amplitude at the start', (0.0, 3.0)),
    'knob_rate': ('random turns of the gain knob per second (Poisson)', (0.0, 1e3)),
    'knob_step': ('rad: standard deviation of one knob turn', (0.0, 3.0)),
    'noise_std': ('mW: power meter noise (system (3): v ~ N(0, 100))', (0.0, 1e3)),
    **BLOCKAGE_HELP,
}


@dataclass(frozen=True)
class SimulatorConfig:
    """The node's settings, read once: the link and how it is played out."""

    link: OwcLinkConfig
    time_factor: float
    duration: float
    start_time: float
    publish_invalid: bool
    wait_for_subscribers: int
    frame_id: str
    angle_name: str


class PowerMeterSimulator(LinkSimulatorNode):
    """Publish simulated received power and the true angle at `rate` (times time_factor)."""

    SENSOR_TOPIC = POWER_TOPIC

    def __init__(self, *, context=None, parameter_overrides: Optional[list] = None,
                 node_name: str = NODE_NAME, namespace: Optional[str] = None) -> None:
        super().__init__(node_name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides)
        self.link = OwcLink(self.config.link)
        self.add_on_set_parameters_callback(self._validate)
        link = self.config.link
        self.total = int(round(self.config.duration * link.rate)) or None
        self.published = 0
        period = max(1.0 / (link.rate * self.config.time_factor), 1e-3)
        self.timer = self.create_timer(period, self._tick)
        self.start_diagnostics(link.rate * self.config.time_factor, lambda: self.published)
        self.get_logger().info(
            f'simulating the OWC link at {link.rate:g} Hz x {self.config.time_factor:g}, '
            f'seed {link.seed}, blockage {link.blockage}'
            + (f', {self.total} samples' if self.total else ''))

    def _declare(self) -> None:
        declare_config_fields(self, OwcLinkConfig, LINK_HELP)
        D = ParameterType.PARAMETER_DOUBLE
        self.declare_parameter('time_factor', 1.0, descriptor(
            'play the stream this many times faster than the stamps advance '
            '(a 300 s run at 1 Hz with 30: 10 s)', (1e-3, 1e4), D))
        self.declare_parameter('duration', 0.0, descriptor(
            'seconds of stamped data to publish, then stop; 0: forever',
            (0.0, 1e9), D))
        self.declare_parameter('start_time', 0.0, descriptor(
            'stamp (s) of sample 0; 0: the node clock at the first tick',
            (0.0, 1e10), D))
        self.declare_parameter('wait_for_subscribers', 0, ParameterDescriptor(
            description='hold sample 0 until received_power has this many subscribers',
            type=ParameterType.PARAMETER_INTEGER, read_only=True))
        self.declare_parameter('publish_invalid', False, ParameterDescriptor(
            description='publish readings <= 0 as they are (true) or leave a gap (false)',
            type=ParameterType.PARAMETER_BOOL))
        self.declare_parameter('frame_id', 'power_meter', descriptor(
            'frame_id of received_power', None, ParameterType.PARAMETER_STRING))
        self.declare_parameter('angle_name', 'theta', descriptor(
            'joint name of the angle on true_angle', None,
            ParameterType.PARAMETER_STRING))

    def _read(self) -> SimulatorConfig:
        link = config_from_parameters(self, OwcLinkConfig, OwcLinkError)
        p = {name: self.get_parameter(name).value for name in (
            'time_factor', 'duration', 'start_time', 'publish_invalid', 'wait_for_subscribers',
            'frame_id', 'angle_name')}
        return SimulatorConfig(link, p['time_factor'], p['duration'], p['start_time'],
                               p['publish_invalid'], p['wait_for_subscribers'], p['frame_id'],
                               p['angle_name'])

    def _validate(self, changes: list) -> SetParametersResult:
        """Only publish_invalid changes at run time; the seeded stream is fixed at start."""
        for p in changes:
            if p.name == 'publish_invalid':
                if not isinstance(p.value, bool):
                    return SetParametersResult(successful=False,
                                               reason='publish_invalid must be a bool')
                self.config = replace(self.config, publish_invalid=p.value)
        return SetParametersResult(successful=True)

    def _tick(self) -> None:
        now = self.get_clock().now().nanoseconds
        if not self.started(now):
            return
        link, factor = self.config.link, self.config.time_factor
        due = int((now - self.start_ns) / NS * factor * link.rate) + 1
        if self.total is not None:
            due = min(due, self.total)
        n = min(due - self.published, MAX_BATCH)
        if n > 0:
            self.publish_samples(self.link.generate(n))
        if self.total is not None and self.published >= self.total:
            self.timer.cancel()
            self.get_logger().info(f'published all {self.total} samples; stopping')

    def publish_samples(self, s: Samples) -> None:
        """
        Publish a batch of samples: the power unless it is a gap, then the truth always.

        The power goes first, so that a client that stops at the last true angle has had
        the last reading sent before it (the demo's collector stopped one reading short).
        """
        cfg = self.config
        var = cfg.link.noise_std ** 2
        for i in range(len(s)):
            stamp = self.stamp0_ns + int(round(int(s.index[i]) * NS / cfg.link.rate))
            if not s.blocked[i] and (s.reading[i] > 0 or cfg.publish_invalid):
                self.sensor_pub.publish(conversions.power_to_msg(stamp, s.reading[i], var,
                                                                 frame_id=cfg.frame_id))
            self.truth_pub.publish(conversions.angle_to_msg(stamp, [s.theta[i]],
                                                            [cfg.angle_name]))
        self.published += len(s)


DESCRIPTION = ('Simulated power meter of the vibration-induced '
               'intermittent OWC link (Cai et al. IV). Parameters: --ros-args --params-file '
               'config/power_meter_simulator.yaml or -p name:=value')


def main(args: Optional[list] = None) -> None:
    """Run the node until Ctrl-C or shutdown."""
    run_node(PowerMeterSimulator, name=NODE_NAME, description=DESCRIPTION,
             startup_errors=(OwcLinkError,), args=args)


if __name__ == '__main__':
    main()
