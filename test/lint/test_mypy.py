"""mypy passes on the ROS-free layers (core/, owc/, led/) with the settings in setup.cfg."""

from pathlib import Path

from mypy import api

REPO = Path(__file__).resolve().parents[2]


def test_mypy_is_clean_on_core_owc_and_led(monkeypatch):
    monkeypatch.chdir(REPO)
    out, err, rc = api.run(['--config-file', str(REPO / 'setup.cfg')])
    assert rc == 0, out + err
