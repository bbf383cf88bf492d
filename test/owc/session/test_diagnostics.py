"""The session's diagnostics: long gaps warn, silent input is an error, a slow one a warning."""

import numpy as np
from owc_streams import feed, owc_session, power, T0, THETA
import pytest

from tskf_ros.core.units import NS


def test_long_gap_warns():
    session = owc_session(max_gap=5.0)
    feed(session, np.array([1.0, 2.0, 9.0, 10.0]), np.full(4, 200.0))
    level, message, values = session.diagnostics()
    assert level == 'WARN' and 'max_gap' in message and values['gap_max_s'] == 7.0
    assert session.diagnostics()[0] == 'OK'


def test_silent_input_is_an_error_and_a_slow_one_a_warning():
    s = owc_session(stale_timeout=10.0, min_rate_fraction=0.5, rate_window=10.0)
    now = T0
    for k in range(12):                               # 1 Hz: OK
        s.add(now, power(THETA), now_ns=now)
        now += NS
    assert s.diagnostics(now_ns=now)[0] == 'OK'
    for k in range(6):                                # 0.25 Hz over 10 s: WARN
        now += 4 * NS
        s.add(now - 2 * NS, power(THETA), now_ns=now)
    level, message, values = s.diagnostics(now_ns=now)
    assert level == 'WARN' and 'below 0.5' in message
    assert values['input_rate_hz'] == pytest.approx(0.2, abs=0.11)
    level, message, _ = s.diagnostics(now_ns=now + 11 * NS)   # nothing for 11 s
    assert level == 'ERROR' and 'no input' in message
    fresh = owc_session(stale_timeout=10.0)
    fresh.diagnostics(now_ns=T0)
    assert fresh.diagnostics(now_ns=T0 + 10 * NS)[0] == 'ERROR'   # never any input
