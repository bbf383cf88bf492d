"""The commands the README and doc/ name exist: tskf_NAME in the venv, NAME for `ros2 run`."""

import os
from pathlib import Path
import re
import sys

from test_colcon_build import console_scripts

REPO_ROOT = Path(__file__).resolve().parent.parent
README = REPO_ROOT / 'README.md'
PREFIX = 'tskf_'
ROS2_RUN = re.compile(r'ros2 run tskf_ros (\w+)')
# anywhere in a command: tskf_NAME (tskf_ros itself is the package), python -m MODULE,
# python bench/SCRIPT.py
PREFIXED = re.compile(r'\btskf_(\w+)')
MODULE = re.compile(r'\bpython3? -m (tskf_ros(?:\.\w+)+)(?![.\w<])')
BENCH = re.compile(r'\bpython3? (bench/\w+\.py)')


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


def documentation() -> dict:
    """Return {path relative to the repository: text} of every markdown page users read."""
    paths = [README, REPO_ROOT / 'bags' / 'README.md']
    for top in ('doc', 'docs'):       # doc/figures is a link to docs: read once, as docs
        paths += sorted(path for path in (REPO_ROOT / top).rglob('*.md')
                        if '_build' not in path.parts)
    return {str(path.relative_to(REPO_ROOT)): path.read_text()
            for path in paths if path.is_file()}


def placeholder(name: str) -> bool:
    """Return whether a command name is a placeholder such as NAME, not a name."""
    return name.isupper()


def wrong_names(text: str) -> list:
    """Return the executables, modules and scripts a page's commands name that do not exist."""
    scripts = set(console_scripts())
    wrong = []
    for command in readme_commands(text):
        for name in PREFIXED.findall(command) + ROS2_RUN.findall(command):
            if name != 'ros' and not placeholder(name) and name not in scripts:
                wrong.append(f'{name} in {command!r}')
        for module in MODULE.findall(command):
            path = REPO_ROOT.joinpath(*module.split('.'))
            if not (path.with_suffix('.py').is_file() or (path / '__main__.py').is_file()):
                wrong.append(f'module {module} in {command!r}')
        for script in BENCH.findall(command):
            if not (REPO_ROOT / script).is_file():
                wrong.append(f'script {script} in {command!r}')
    return wrong


def test_the_documentation_names_only_commands_that_exist():
    pages = documentation()
    assert 'README.md' in pages and 'doc/index.md' in pages, sorted(pages)
    wrong = {path: wrong_names(text) for path, text in pages.items()}
    wrong = {path: names for path, names in wrong.items() if names}
    assert not wrong, f'commands named in the documentation that do not exist: {wrong}'
    bare = {path: sorted(named(readme_commands(text))[2]) for path, text in pages.items()}
    bare = {path: names for path, names in bare.items() if names}
    assert not bare, f'bare executable names (write tskf_NAME in the venv): {bare}'


def test_wrong_names_finds_what_does_not_exist():
    # the check itself, on commands that name a missing executable, module and script
    text = ('```bash\ntskf_no_such_tool x\nros2 run tskf_ros no_such_node\n'
            'python -m tskf_ros.no_such_module\npython bench/no_such_bench.py\n```\n'
            '`tskf_play --help`, `python -m tskf_ros.bag.player`, `tskf_NAME`\n')
    wrong = wrong_names(text)
    assert len(wrong) == 4, wrong
    assert all(name in ' '.join(wrong) for name in (
        'no_such_tool', 'no_such_node', 'tskf_ros.no_such_module', 'bench/no_such_bench.py'))


def test_the_readme_names_its_commands_as_they_are_installed():
    prefixed, ros2_run, bare = named(readme_commands(README.read_text()))
    assert {'tskf_record', 'tskf_play'} <= prefixed
    # a bare name is not on the venv's PATH (play would be SoX's): the README must not use it
    assert not bare, f'the README runs {sorted(bare)} by bare names; write tskf_NAME'
    ros2_run = {name for name in ros2_run if not placeholder(name)}
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
