"""The numerical core must import without rclpy: only tskf_ros.nodes (and tskf_ros.bag) may."""

from pathlib import Path
import subprocess
import sys

import pytest

REPO_ROOT = Path(__file__).resolve().parent.parent
PACKAGE = 'tskf_ros'
# Subpackages that legitimately need rclpy.
ROS_SUBPACKAGES = ('nodes', 'bag')

CHECK = (
    'import sys; import {module}; '
    "leaked = sorted(m for m in sys.modules if m == 'rclpy' or m.startswith('rclpy.')); "
    "assert not leaked, 'importing {module} imported ' + ', '.join(leaked)"
)


def core_modules():
    """Return the dotted names of all modules of the package outside ROS_SUBPACKAGES."""
    modules = []
    for path in sorted((REPO_ROOT / PACKAGE).rglob('*.py')):
        parts = path.relative_to(REPO_ROOT).with_suffix('').parts
        if len(parts) > 1 and parts[1] in ROS_SUBPACKAGES:
            continue
        if parts[-1] == '__init__':
            parts = parts[:-1]
        modules.append('.'.join(parts))
    return modules


def test_core_modules_found():
    assert PACKAGE in core_modules()


@pytest.mark.parametrize('module', core_modules())
def test_core_module_does_not_import_rclpy(module):
    result = subprocess.run(
        [sys.executable, '-c', CHECK.format(module=module)],
        cwd=REPO_ROOT, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
