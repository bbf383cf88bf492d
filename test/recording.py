"""What the tests that run `record` as a process share: waiting for it, cleaning up."""

import time


def wait_until_recording(pub, proc, timeout: float, topic: str) -> None:
    """Poll the graph until the recorder process subscribes to pub's topic; fail if it exits."""
    deadline = time.monotonic() + timeout
    while pub.get_subscription_count() == 0:
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < deadline, f'the recorder never subscribed to {topic}'
        time.sleep(0.05)          # polling a condition, with a deadline


def stop(proc, node, context) -> None:
    """Kill the recorder if it still runs; destroy the test's node and context."""
    if proc.poll() is None:
        proc.kill()
    node.destroy_node()
    context.try_shutdown()
