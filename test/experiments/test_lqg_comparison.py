"""The LQG-against-P comparison (tskf_ros.experiments.lqg_comparison): its JSON and PNG."""

import json

from tskf_ros.experiments import lqg_comparison


def test_comparison_writes_both_controllers(tmp_path, capsys):
    out, png = tmp_path / 'c.json', tmp_path / 'c.png'
    assert lqg_comparison.main(['--runs', '3', '--steps', '30', '--betas', '0,14',
                                '--json', str(out), '--png', str(png)]) == 0
    data = json.loads(out.read_text())
    assert set(data['sweep']) == {'p', 'lqg'} and len(data['sweep']['lqg']) == 2
    assert data['effort']['lqg']['noise_v'] == 1.0
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
