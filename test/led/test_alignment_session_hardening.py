"""
The alignment session under absurd inputs: neither a crash nor a wedged filter.

Each test states the case that failed before its fix.  The session is driven directly
(no DDS); the node's cases are in test/nodes/, the estimator session's in test/owc/session/.
"""

import numpy as np
import pytest

from tskf_ros.core.units import MAX_STAMP_NS, NS
from tskf_ros.led.alignment_session import AlignmentConfig, AlignmentSession
from tskf_ros.led.pat_config import PatConfig

T0 = 1_700_000_000 * NS


# -- the alignment session ---------------------------------------------------------------

def aligner(**extra):
    # the scanning EKF alone (pat.enabled false): the supervisor's cases are below
    return AlignmentSession(AlignmentConfig(**{'pat': PatConfig(enabled=False), **extra}))


def test_alignment_gates_a_1e308_intensity_and_the_base_stays_in_its_limits():
    # before: the base command went to about -8e305 rad, and stayed there
    a = aligner()
    stamps = [T0 + k * NS // 20 for k in range(400)]
    outs = []
    for k, t in enumerate(stamps):
        z = 1e308 if k == 200 else 2.0
        outs.append(a.add(t, z))
    assert outs[200].status == 'missing' and outs[200].reason == 'gated'
    commands = [o.command for o in outs if o.command is not None]
    assert all(-360.0 <= c <= 360.0 for c in commands)
    turns = np.abs(np.diff([0.0] + commands))
    assert turns.max() <= 45.0 + 1e-9
    assert outs[-1].status == 'used'


def test_alignment_commands_are_clamped_and_the_ekf_told():
    a = aligner(max_step=1.0, base_limits=(-3.0, 3.0), x0=(2.0, 20.0))
    outs = [a.add(T0 + k * NS // 20, 2.0) for k in range(50)]
    cmds = [o.command for o in outs]
    assert all(-3.0 - 1e-12 <= c <= 3.0 + 1e-12 for c in cmds)
    assert max(abs(b - c) for b, c in zip([0.0] + cmds, cmds)) <= 1.0 + 1e-12
    assert int(a.diagnostics()[0].as_dict()['Commands clamped']) > 0
    with pytest.raises(ValueError, match='base_initial'):
        AlignmentConfig(base_initial=10.0, base_limits=(-3.0, 3.0))


@pytest.mark.parametrize('bad', [1e308, 1e200, float('inf'), -1e308])
def test_the_supervisor_survives_absurd_intensities_while_searching(bad):
    # three absurd readings in the dark of a cold search, then light from sample 100:
    # finite commands within the joint limits, and tracking at the end
    a = AlignmentSession(AlignmentConfig())
    outs = [a.add(T0 + k * NS // 20, bad if 5 <= k < 8 else (2.0 if k > 100 else 0.0))
            for k in range(400)]
    commands = [o.command for o in outs if o.command is not None]
    assert len(commands) == 400 - a.stats.rejected.total()
    assert all(-360.0 <= c <= 360.0 for c in commands)
    assert a.pat_state == 'tracking'


def test_alignment_rejects_stamps_beyond_int32_seconds():
    a = AlignmentSession(AlignmentConfig())
    assert a.add(MAX_STAMP_NS + 1, 1.0).reason == 'stamp_range'


def test_alignment_restarts_itself_on_an_absurd_state_and_reports_error():
    a = aligner(gate=0.0)                            # no gate: 1e200 V reaches the EKF
    outs = [a.add(T0 + k * NS // 20, 2.0) for k in range(3)]
    outs.append(a.add(T0 + 3 * NS // 20, 1e200))
    assert outs[-1].reason == 'filter_error' and 'state_limit' in outs[-1].message
    aligner_status = a.diagnostics()[0]
    assert aligner_status.level == 2
    assert aligner_status.as_dict()['Resets (state_health)'] == '1'
