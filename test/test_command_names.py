"""The command names the README uses exist: tskf_NAME in the venv, NAME for `ros2 run`."""

import os
from pathlib import Path
import re
import sys

from test_colcon_build import console_scripts

REPO_ROOT = Path(__file__).resolve().parent.parent
README = REPO_ROOT / 'README.md'
PREFIX = 'tskf_'
ROS2_RUN = re.compile(r'ros2 run tskf_ros (\w+)')


def readme_commands(text: str) -> list:
    """
    Return the commands of a README: the lines of its bash blocks and its inline code spans.

    Comments and blank lines are left out; each command is its text, stripped.
    """
    commands = []
    for block in re.findall(r'```bash\n(.*?)```', text, flags=re.S):
        commands += [line.strip() for line in block.splitlines()
                     if line.strip() and not line.strip().startswith('#')]
    outside = re.sub(r'```.*?```', '', text, flags=re.S)
    commands += [span.strip() for span in re.findall(r'`([^`\n]+)`', outside)]
    return commands


def named(commands: list) -> tuple:
    """Split commands into (tskf_ names, ros2 run names, bare executable names with args)."""
    scripts = set(console_scripts())
    prefixed, ros2_run, bare = set(), set(), set()
    for command in commands:
        ros2_run.update(ROS2_RUN.findall(command))
        first, _, rest = command.partition(' ')
        if first.startswith(PREFIX) and first[len(PREFIX):] in scripts:
            prefixed.add(first)
        elif first in scripts and rest:
            bare.add(first)
    return prefixed, ros2_run, bare


def test_the_readme_names_its_commands_as_they_are_installed():
    prefixed, ros2_run, bare = named(readme_commands(README.read_text()))
    assert {'tskf_record', 'tskf_play'} <= prefixed
    # a bare name is not on the venv's PATH (play would be SoX's): the README must not use it
    assert not bare, f'the README runs {sorted(bare)} by bare names; write tskf_NAME'
    assert ros2_run <= set(console_scripts()), sorted(ros2_run - set(console_scripts()))


def test_the_venv_has_every_executable_under_its_prefixed_name_only():
    # ./run links .venv/bin/tskf_NAME to .venv/lib/tskf_ros/NAME (the editable install's
    # script_dir, as colcon's lib/tskf_ros); the generic names stay off the PATH
    bin_dir = Path(sys.prefix) / 'bin'
    lib_dir = Path(sys.prefix) / 'lib' / 'tskf_ros'
    for name in console_scripts():
        exe = bin_dir / f'{PREFIX}{name}'
        assert exe.is_file() and os.access(exe, os.X_OK), \
            f'{exe} is missing (./run makes it; run ./run once)'
        assert exe.resolve() == (lib_dir / name).resolve()
        assert not (bin_dir / name).exists() or name not in ('play', 'record'), \
            f'{bin_dir / name} would shadow other programs'
