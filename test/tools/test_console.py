# Copyright 2026 The tskf_ros authors
# SPDX-License-Identifier: Apache-2.0
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
Ctrl-C on a console script in any phase: exit 130 (or the tool's own 0), never a traceback.

Each tool runs as a process through its console-script function of tskf_ros.tools.console,
as the installed executable runs it, and takes SIGINT at a point found by polling a
condition with a deadline (no sleeps): at once, while its third-party modules load (their
shared objects appear in /proc/PID/maps), and for the tools that run until stopped, once
they are running (their first output, or the recording directory).  The documented
`python -m` commands take SIGINT once they work (a first line, their output table, their
bag open): exit 130, only the tool's own lines on stderr, every output file whole or absent.
"""

import ast
import json
import os
from pathlib import Path
import random
import re
import signal
import subprocess
import sys
import time
import weakref

from bag.helpers import make_bag, TIMEOUT
from entry_points import console_script_targets
import pytest

from tskf_ros.tools import console

REPO = Path(__file__).resolve().parent.parent.parent
INTERRUPTED = 130
POLL = 0.002                    # s between two looks at a condition (not a synchronisation)
# s: a bound on a process that may compile the kernels first (numba without a cache of
# them: about 20 s idle, more than TIMEOUT on a loaded 2-core machine under colcon test)
COMPILE_TIMEOUT = 600.0


def start(tool: str, args: list, tmp_path: Path) -> tuple[subprocess.Popen, Path]:
    """Start one console script (as its executable does) with stderr to a file."""
    err = tmp_path / f'{tool}.err'
    code = f'from tskf_ros.tools.console import {tool}; {tool}()'
    with open(err, 'w') as f:
        proc = subprocess.Popen([sys.executable, '-c', code, *args], cwd=tmp_path,
                                stdout=subprocess.DEVNULL, stderr=f)
    return proc, err


def wait_for(condition, proc: subprocess.Popen, timeout: float = TIMEOUT) -> bool:
    """Poll condition until it holds (True) or proc ends (False); fail after timeout s."""
    deadline = time.monotonic() + timeout
    while not condition():
        if proc.poll() is not None:
            return False
        assert time.monotonic() < deadline, 'the condition never held'
        time.sleep(POLL)
    return True


def loading_site_packages(pid: int) -> bool:
    """Return whether the process has mapped a shared object of a third-party package."""
    try:
        maps = Path(f'/proc/{pid}/maps').read_text()
    except OSError:
        return False
    return any('-packages/' in line and '.so' in line for line in maps.splitlines())


def interrupt(proc: subprocess.Popen, err: Path) -> tuple[int, str]:
    """Send SIGINT (if it still runs); return its exit status and stderr."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        code = proc.wait(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    return code, err.read_text()


def test_every_console_script_goes_through_the_wrapper():
    targets = console_script_targets()
    assert set(targets) == set(console.TOOLS)
    for name, target in targets.items():
        # the installed script calls the tool's function, or its quiet wrapper here
        assert target in (console.TOOLS[name], f'tskf_ros.tools.console:{name}'), name
        assert callable(getattr(console, name))


@pytest.mark.parametrize('tool', sorted(console.TOOLS))
def test_ctrl_c_while_the_modules_load_is_quiet(tool, tmp_path):
    # --help: the tool ends by itself (0) once loaded; a SIGINT before that is 130
    proc, err = start(tool, ['--help'], tmp_path)
    wait_for(lambda: loading_site_packages(proc.pid), proc)
    code, text = interrupt(proc, err)
    assert 'Traceback' not in text and code in (INTERRUPTED, 0), (code, text)
    assert len(text.splitlines()) <= 1, text


@pytest.mark.parametrize('tool', ['play', 'sweep', 'timescale_estimator'])
def test_ctrl_c_at_once_is_quiet(tool, tmp_path):
    # before the interpreter installs its handler, SIGINT ends it as the signal does
    proc, err = start(tool, ['--help'], tmp_path)
    code, text = interrupt(proc, err)
    assert 'Traceback' not in text and code in (INTERRUPTED, 0, -signal.SIGINT), (code, text)


@pytest.fixture
def sigint_restored():
    """Put back the SIGINT handler the console wrapper replaces in this process."""
    previous = signal.getsignal(signal.SIGINT)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    return make_bag(tmp_path_factory.mktemp('console') / 'bag', [0.0, 0.5, 1.0, 30.0])


def test_ctrl_c_while_play_plays_is_quiet(bag, tmp_path):
    proc, err = start('play', [str(bag), '--loop', '--disable-keyboard-controls'], tmp_path)
    assert wait_for(lambda: loading_site_packages(proc.pid) and 'rclpy' in Path(
        f'/proc/{proc.pid}/maps').read_text(), proc)
    code, text = interrupt(proc, err)
    assert 'Traceback' not in text and code in (INTERRUPTED, 0), (code, text)


def test_ctrl_c_while_record_records_is_quiet(tmp_path):
    out = tmp_path / 'out'
    out.mkdir()
    proc, err = start('record', ['-o', str(out / 'bag'), '--topics', '/x:std_msgs/msg/String'],
                      tmp_path)
    assert wait_for(lambda: any(out.iterdir()), proc), err.read_text()   # the bag begun
    code, text = interrupt(proc, err)
    assert 'Traceback' not in text and code in (INTERRUPTED, 0), (code, text)


def test_ctrl_c_while_a_node_runs_is_quiet(tmp_path):
    proc, err = start('timescale_estimator', ['--ros-args', '--log-level', 'info'], tmp_path)
    assert wait_for(lambda: err.stat().st_size > 0, proc), err.read_text()
    code, text = interrupt(proc, err)
    assert 'Traceback' not in text and code in (INTERRUPTED, 0), (code, text)


def test_the_wrapper_turns_an_interrupt_into_130(monkeypatch, capsys, sigint_restored):
    def interrupted():
        raise KeyboardInterrupt
    monkeypatch.setitem(console.TOOLS, 'play', f'{__name__}:interrupted_entry')
    monkeypatch.setattr(sys.modules[__name__], 'interrupted_entry', interrupted, raising=False)
    with pytest.raises(SystemExit) as exit_:
        console.play()
    assert exit_.value.code == INTERRUPTED and capsys.readouterr().err == ''


def test_the_wrapper_passes_the_tools_status_on(monkeypatch, sigint_restored):
    monkeypatch.setitem(console.TOOLS, 'reindex', f'{__name__}:status_entry')
    monkeypatch.setattr(sys.modules[__name__], 'status_entry', lambda: 3, raising=False)
    with pytest.raises(SystemExit) as exit_:
        console.reindex()
    assert exit_.value.code == 3


@pytest.mark.parametrize('returned, status', [(None, None), (4, 4)])   # None: exit 0
def test_run_as_main_passes_the_status_on(returned, status, sigint_restored):
    with pytest.raises(SystemExit) as exit_:
        console.run_as_main(lambda: returned)
    # once main has ended, a Ctrl-C no longer interrupts the exit
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    assert exit_.value.code == status


def test_run_as_main_is_quiet_on_a_ctrl_c_while_main_cleans_up(capsys, sigint_restored):
    cleaned = []

    def main() -> int:
        try:
            signal.raise_signal(signal.SIGINT)          # the first Ctrl-C: main stops...
        except KeyboardInterrupt:
            print('tool: interrupted', file=sys.stderr)
            signal.raise_signal(signal.SIGINT)          # ...and a second one in its cleanup
            cleaned.append(True)                        # (not reached)
        return 0
    with pytest.raises(SystemExit) as exit_:
        console.run_as_main(main)
    assert exit_.value.code == INTERRUPTED and not cleaned
    assert capsys.readouterr().err == 'tool: interrupted\n'     # the tool's own line only


FAKE_TOOL = """
import os, signal
try:
    os.kill(os.getpid(), signal.SIGINT)     # Ctrl-C inside an extension's import:
    for _ in range(10 ** 7):                 # numpy turns it into an ImportError
        pass
except KeyboardInterrupt:
    raise ImportError('PyCapsule_Import could not import module "datetime"')
def main():
    return 0
"""


@pytest.mark.parametrize('interrupt', [True, False])
def test_an_error_after_a_ctrl_c_is_the_interrupt(tmp_path, monkeypatch, interrupt,
                                                  sigint_restored):
    (tmp_path / 'fake_tool.py').write_text(
        FAKE_TOOL if interrupt else FAKE_TOOL.replace('os.kill(os.getpid(), signal.SIGINT)',
                                                      'raise KeyboardInterrupt'))
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(console.TOOLS, 'fake', 'fake_tool:main')
    if interrupt:
        with pytest.raises(SystemExit) as end:
            console.run('fake')
        assert end.value.code == INTERRUPTED
    else:
        # the same error with no Ctrl-C is a real error: it is raised
        with pytest.raises(ImportError, match='PyCapsule_Import'):
            console.run('fake')


def test_an_error_after_a_ctrl_c_taken_by_the_tools_own_handler_is_the_interrupt(
        capsys, sigint_restored):
    # the tool's own SIGINT handler replaces the wrapper's (fit_noise's reader does), and a
    # library turns the KeyboardInterrupt into another error (numba's dispatcher: a
    # SystemError "returned a result with an exception set"): still exit 130, nothing said
    def main() -> int:
        def own(signum, frame):
            raise KeyboardInterrupt
        previous = signal.signal(signal.SIGINT, own)
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:
            raise SystemError('CPUDispatcher(<function update_predict>) returned a result '
                              'with an exception set') from None
        finally:
            signal.signal(signal.SIGINT, previous)
        return 0
    with pytest.raises(SystemExit) as exit_:
        console.run_as_main(main)
    assert exit_.value.code == INTERRUPTED and capsys.readouterr().err == ''


def test_the_same_error_with_no_ctrl_c_is_raised(sigint_restored):
    def main() -> int:
        raise SystemError('a real bug')
    with pytest.raises(SystemError, match='a real bug'):
        console.run_as_main(main)


def test_a_ctrl_c_swallowed_by_a_weakref_callback_is_delivered_again(capsys, sigint_restored):
    # a Ctrl-C that lands in a weakref callback (importlib's _get_module_lock.<locals>.cb
    # while modules load) is only reported by Python ("Exception ignored in ...") and lost:
    # the wrapper drops the report and interrupts the tool again, which then ends with 130
    ended = []

    def main() -> int:
        class Thing:
            pass
        thing = Thing()
        ref = weakref.ref(thing, lambda _: signal.raise_signal(signal.SIGINT))
        del thing                                   # the callback runs: SIGINT inside it
        assert ref() is None
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:          # until the interrupt comes again
            pass
        ended.append('the interrupt never came again')
        return 0
    with pytest.raises(SystemExit) as exit_:
        console.run_as_main(main)
    assert exit_.value.code == INTERRUPTED and ended == []
    assert capsys.readouterr().err == ''


def test_the_wrapper_gives_the_wakeup_fd_and_the_unraisable_hook_back(sigint_restored):
    hook = sys.unraisablehook
    with pytest.raises(SystemExit):
        console.run_as_main(lambda: 0)
    assert sys.unraisablehook is hook
    assert signal.set_wakeup_fd(-1) == -1           # none was set before: none is now


NUMBA_TOOL = """
import sys
from pathlib import Path
import numpy as np
from tskf_ros.bag.progress import Interrupts
from tskf_ros.core import kalman

def main():
    x, P, d, Bu = np.zeros(2), np.eye(2), np.zeros(1), np.zeros(2)
    F, Q, H, R = np.eye(2), np.eye(2), np.ones((1, 2)), np.eye(1)
    with Interrupts():                              # its own handler, as fit_noise's
        kalman.warm_up()
        Path(sys.argv[1]).write_text('running')
        while True:                                 # the compiled kernels, until Ctrl-C
            kalman.update_predict(x, P, np.zeros(1), H, R, d, F, Q, Bu)
"""


def test_ctrl_c_while_the_compiled_kernels_run_under_the_tools_own_handler(tmp_path):
    (tmp_path / 'numba_tool.py').write_text(NUMBA_TOOL)
    ready, err = tmp_path / 'ready', tmp_path / 'numba_tool.err'
    code = ('import sys; sys.path.insert(0, sys.argv[2]); from tskf_ros.tools import console; '
            "console.TOOLS['numba_tool'] = 'numba_tool:main'; console.run('numba_tool')")
    with open(err, 'w') as f:
        proc = subprocess.Popen([sys.executable, '-c', code, str(ready), str(tmp_path)],
                                cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=f)
    try:
        assert wait_for(ready.exists, proc, COMPILE_TIMEOUT), err.read_text()
        code, text = interrupt(proc, err)
    finally:                                        # its loop never ends by itself
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert code == INTERRUPTED and text == '', (code, text)


def main_blocks() -> dict:
    """Return {module: its `if __name__ == '__main__':` block (ast.If)} of the package."""
    blocks = {}
    for path in sorted((REPO / 'tskf_ros').rglob('*.py')):
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.If) and ast.unparse(node.test) == "__name__ == '__main__'":
                blocks['.'.join(path.relative_to(REPO).with_suffix('').parts)] = node
    return blocks


def test_every_main_block_runs_through_run_as_main():
    blocks = main_blocks()
    assert {t.partition(':')[0] for t in console.TOOLS.values()} <= set(blocks)
    entries = {t.partition(':')[0]: t.partition(':')[2] for t in console.TOOLS.values()}
    for module, block in blocks.items():
        # the function the console script runs, else the module's main
        expected = ['from tskf_ros.tools.console import run_as_main',
                    f'run_as_main({entries.get(module, "main")})']
        assert [ast.unparse(statement) for statement in block.body] == expected, module


def start_module(module: str, args: list, tmp_path: Path) -> tuple[subprocess.Popen, Path, Path]:
    """Start `python -m module args` in tmp_path; its stdout and stderr go to files."""
    out, err = tmp_path / 'stdout', tmp_path / 'stderr'
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=os.environ.get('ROS_DOMAIN_ID', str(random.randint(1, 100))),
               OPENBLAS_NUM_THREADS='1')
    with open(out, 'w') as o, open(err, 'w') as e:
        proc = subprocess.Popen([sys.executable, '-m', module, *map(str, args)], cwd=tmp_path,
                                stdout=o, stderr=e, env=env)
    return proc, out, err


def has_open(pid: int, name: str) -> bool:
    """Return whether the process holds a file of this name open."""
    try:
        return any(os.readlink(fd).endswith(name) for fd in Path(f'/proc/{pid}/fd').iterdir())
    except OSError:
        return False


def whole_or_absent(paths: list) -> list:
    """Check each output is whole (JSON parses, PNG ends with IEND) or absent; return those."""
    present = [p for p in paths if p.exists()]
    for p in present:
        if p.suffix == '.json':
            json.loads(p.read_text())
        elif p.suffix == '.png':
            assert p.read_bytes().endswith(b'IEND\xaeB`\x82'), p
    leftovers = [q.name for p in paths if p.parent.is_dir() for q in p.parent.iterdir()
                 if q.name.startswith('.') and 'part' in q.name]
    assert leftovers == [], leftovers
    return present


def test_ctrl_c_while_alignment_mc_runs(tmp_path):
    # enough work that the interrupt lands inside the sweep, which it ends at once
    outputs = [tmp_path / 'res' / 'fig10.json', tmp_path / 'res' / 'fig10.png']
    proc, _, err = start_module('tskf_ros.experiments.alignment_mc', [
        '--runs', 2, '--noise-levels', ','.join(['0.5'] * 50), '--algorithms', 'ekf',
        '--json', outputs[0], '--png', outputs[1]], tmp_path)
    assert wait_for(lambda: '[alignment_mc] g at' in err.read_text(), proc), err.read_text()
    code, text = interrupt(proc, err)
    assert code == INTERRUPTED, text
    # its own progress lines only
    assert all(line.startswith('[alignment_mc] ') for line in text.splitlines()), text
    assert whole_or_absent(outputs) == []


def test_ctrl_c_while_reproduce_runs(tmp_path):
    out = tmp_path / 'results'
    proc, stdout, err = start_module('tskf_ros.experiments.reproduce', [
        '--out', out, '--iterations', 15, '--long-iterations', 2000], tmp_path)
    assert wait_for(lambda: '[example 3.20]' in stdout.read_text(), proc), err.read_text()
    code, text = interrupt(proc, err)
    assert code == INTERRUPTED and text == ''
    # the files of the finished steps are whole; the summary (written last) is absent
    written = whole_or_absent(sorted(out.iterdir()))
    assert written and not (out / 'summary.json').exists()


def test_ctrl_c_while_fit_noise_reads(tmp_path):
    # its own one line after an interrupt: 'interrupted; nothing written'
    outputs = [tmp_path / 'fit.yaml', tmp_path / 'fit.json']
    proc, _, err = start_module('tskf_ros.experiments.fit_noise', [
        REPO / 'bags' / 'owc_ge_1khz', '--params-file', REPO / 'config' / 'owc_estimator.yaml',
        '--out', outputs[0], '--json', outputs[1]], tmp_path)
    assert wait_for(lambda: has_open(proc.pid, 'owc_ge_1khz.mcap'), proc), err.read_text()
    code, text = interrupt(proc, err)
    assert code == INTERRUPTED and 'Traceback' not in text, text
    assert re.fullmatch(r'fit_noise: interrupted; nothing written\n', text), text
    assert [p for p in outputs if p.exists()] == []


def test_ctrl_c_while_sweep_runs(tmp_path):
    # its own one line: how many rows of the table are kept for a resume
    table = tmp_path / 'table.csv'
    proc, _, err = start_module('tskf_ros.experiments.sweep', [
        '--bags', REPO / 'bags' / 'owc_ge_1khz', REPO / 'bags' / 'owc_cai_td_1hz',
        '--set', 'R=1,2,3,4', '--workers', 0, '--no-progress', '--out', table], tmp_path)
    assert wait_for(lambda: table.exists() and table.stat().st_size > 0, proc), err.read_text()
    code, text = interrupt(proc, err)
    assert code == INTERRUPTED, text
    assert re.fullmatch(r'sweep: interrupted: \d+ rows in \S+ kept; the same command '
                        r'resumes\n', text), text
    rows = table.read_text().splitlines(keepends=True)
    assert rows and all(r.endswith('\n') for r in rows)
    assert {r.count(',') for r in rows} == {rows[0].count(',')}   # no row cut short


def test_ctrl_c_while_a_node_runs_as_a_module(tmp_path):
    proc, _, err = start_module('tskf_ros.nodes.timescale_estimator',
                                ['--ros-args', '--log-level', 'info'], tmp_path)
    assert wait_for(lambda: err.stat().st_size > 0, proc), err.read_text()
    code, text = interrupt(proc, err)
    assert 'Traceback' not in text and code in (INTERRUPTED, 0), (code, text)


def test_the_sigint_flag_runs_first_before_the_interrupt(sigint_restored):
    order = []
    flag = console.SigintFlag(first=lambda: order.append('first'))
    try:
        signal.raise_signal(signal.SIGINT)
    except KeyboardInterrupt:
        order.append('interrupt')
    finally:
        flag.restore()
    assert order == ['first', 'interrupt'] and flag.is_set()


# a SIGINT to the child itself before anything of tskf_ros runs: the interpreter and site
# have started, the console runner is not yet imported
SIGINT_FIRST = 'import os, signal; os.kill(os.getpid(), signal.SIGINT); '


@pytest.mark.parametrize('tool', ['alignment', 'timescale_estimator', 'reproduce'])
def test_a_held_start_takes_a_ctrl_c_before_the_runner_imports_as_an_interrupt(tool, tmp_path):
    # started by start_held (as the demo starts its children), the SIGINT waits for the
    # runner's handler: without it, Python's KeyboardInterrupt traceback and exit -2
    err = tmp_path / f'{tool}.err'
    code = SIGINT_FIRST + f'from tskf_ros.tools.console import {tool}; {tool}()'
    with open(err, 'w') as f:
        proc = console.start_held([sys.executable, '-c', code, '--help'], cwd=tmp_path,
                                  stdout=subprocess.DEVNULL, stderr=f)
    assert proc.wait(timeout=TIMEOUT) == INTERRUPTED and err.read_text() == ''


def test_without_a_held_start_the_same_ctrl_c_is_pythons(tmp_path):
    # the control of the test above: the signal really lands before the runner
    code = SIGINT_FIRST + 'from tskf_ros.tools.console import reproduce; reproduce()'
    # (SIGINT at its default in the child: a shell's background job inherits it ignored,
    # and Python then keeps it ignored)
    done = subprocess.run([sys.executable, '-c', code, '--help'], cwd=tmp_path,
                          capture_output=True, text=True, timeout=TIMEOUT,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert done.returncode == -signal.SIGINT and 'KeyboardInterrupt' in done.stderr


def test_a_held_start_leaves_the_parents_mask_and_the_childs_sigint_works(tmp_path):
    before = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    err = tmp_path / 'play.err'
    with open(err, 'w') as f:
        proc = console.start_held([sys.executable, '-c', 'from tskf_ros.tools.console import '
                                   'play; play()', '--help'], cwd=tmp_path,
                                  stdout=subprocess.DEVNULL, stderr=f)
    assert signal.pthread_sigmask(signal.SIG_BLOCK, []) == before
    # once it loads its modules, its runner has taken SIGINT back: the signal ends it
    wait_for(lambda: loading_site_packages(proc.pid), proc)
    code, text = interrupt(proc, err)
    assert code in (INTERRUPTED, 0) and 'Traceback' not in text, (code, text)
