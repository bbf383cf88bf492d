"""The QoS profiles of every topic this package publishes or subscribes to, in one place."""

from rclpy.qos import HistoryPolicy, qos_profile_sensor_data, QoSProfile, ReliabilityPolicy

__all__ = ['DEFAULT_DEPTH', 'DIAGNOSTICS_TOPIC', 'reliable_qos', 'SENSOR_OUTPUT_QOS',
           'sensor_input_qos', 'TRUTH_QOS']

DIAGNOSTICS_TOPIC = '/diagnostics'
# rclpy's system default depth: what /diagnostics and forward_command_controller use
DEFAULT_DEPTH = 10
# a simulated or real sensor publishes as a driver does: rclpy's sensor-data profile
SENSOR_OUTPUT_QOS = qos_profile_sensor_data


def sensor_input_qos(depth: int) -> QoSProfile:
    """
    Return the QoS for a sensor input: best effort, keep last depth.

    A best-effort subscription matches reliable and best-effort publishers alike, so the
    node takes a real driver's sensor-data stream as well as a reliable bag player.
    """
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.BEST_EFFORT)


def reliable_qos(depth: int) -> QoSProfile:
    """Return the QoS of an output every sample of which matters: reliable, keep last depth."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE)


# the evaluation truth of both simulators: reliable, so that a plot has every point
TRUTH_QOS = reliable_qos(100)
