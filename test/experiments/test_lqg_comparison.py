"""The LQG-against-P comparison (tskf_ros.experiments.lqg_comparison): its JSON and PNG."""

import json

import pytest

from tskf_ros.experiments import lqg_comparison


def test_comparison_writes_both_controllers(tmp_path, capsys):
    out, png = tmp_path / 'c.json', tmp_path / 'c.png'
    assert lqg_comparison.main(['--runs', '3', '--steps', '30', '--betas', '0,14',
                                '--json', str(out), '--png', str(png)]) == 0
    data = json.loads(out.read_text())
    assert set(data['sweep']) == {'p', 'lqg'} and len(data['sweep']['lqg']) == 2
    assert data['effort']['lqg']['noise_v'] == 1.0
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_help_prints_and_exits_0(capsys):
    # argparse formats help strings with %: a literal one must be written %%
    with pytest.raises(SystemExit) as exc:
        lqg_comparison.main(['--help'])
    assert exc.value.code == 0
    assert 'write tracking % against beta' in capsys.readouterr().out
