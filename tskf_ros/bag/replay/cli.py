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

"""replay_offline: the command line of the offline replay (bag in, bag or .npz arrays out)."""

import argparse
import os
from pathlib import Path
import sys
import tempfile
from typing import Callable, Optional

import numpy as np
from numpy.typing import NDArray

from tskf_ros.bag.bag_errors import run_main
from tskf_ros.bag.message_types import BagTypeError
from tskf_ros.bag.reader import BagError, error_exit, EXIT_DAMAGED, exit_status
from tskf_ros.bag.replay.loop import FILTER_INPUT, FILTERS, replay
from tskf_ros.bag.replay.npz_output import replay_npz
from tskf_ros.messages import alignment_interface as aligner
from tskf_ros.messages.estimator_interface import (BAG_INPUT_TOPIC, BAG_POWER_TOPIC,
                                                   INPUT_TYPE, INPUT_TYPES, ParamsError)

__all__ = ['console_main', 'default_output', 'main', 'save_npz']

PROG = 'replay_offline'
EPILOG = f"""examples:
  {PROG} bags/owc_cai_td_1hz /tmp/owc_estimated --params-file config/owc_estimator.yaml
  {PROG} --filter alignment bags/led_alignment /tmp/led_aligned \\
      --params-file config/alignment.yaml
  {PROG} bags/owc_ge_1khz --npz /tmp/owc_ge.npz
  {PROG} bags/owc_cai_td_1hz /tmp/owc_smoothed --smooth \
      --params-file config/owc_estimator.yaml

exit status: 0 done; 1 the bag or the parameters could not be used (one-line error);
3 the input was damaged: what came before the damage was processed and written, and the
output's metadata (or meta.damage of the arrays) says where it stopped."""


def default_output(bag: Path, filter: str = 'estimator') -> Path:  # noqa: A002
    """Return <bag>_estimated (_aligned) next to the bag (a .mcap file: without the suffix)."""
    bag = Path(bag)
    stem = bag.stem if bag.suffix == '.mcap' else bag.name
    return bag.parent / f'{stem}{FILTER_INPUT[filter][1]}'


def main(argv: Optional[list[str]] = None) -> int:
    """Run the command line; return the exit status."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Run the time-scale estimator (or the alignment filter) over a '
        "bag without DDS and write a bag with the inputs and the node's outputs.",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('bag', type=Path, help='bag directory (metadata.yaml + .mcap or '
                        '.db3) or a bare .mcap file')
    parser.add_argument('output', type=Path, nargs='?',
                        help='output bag directory (default: <bag>_estimated, with '
                        '--filter alignment <bag>_aligned)')
    parser.add_argument('--filter', choices=FILTERS, default='estimator',
                        help='the node to run: the time-scale estimator (default) or the '
                        'LED alignment node (open loop: its commands do not move the '
                        'recorded receiver)')
    parser.add_argument('--params-file', type=Path,
                        help='parameters of that node, e.g. config/owc_estimator.yaml or '
                        "config/alignment.yaml; default: the node's defaults")
    parser.add_argument('--topic', help=f'measurement topic (default {BAG_POWER_TOPIC}, with '
                        f'--filter alignment {aligner.BAG_INPUT_TOPIC}); types: '
                        + ', '.join(INPUT_TYPES))
    parser.add_argument('--input-topic', help=f"the estimator's input u ({INPUT_TYPE}); "
                        f'default {BAG_INPUT_TOPIC} if the bag has it')
    parser.add_argument('--overwrite', action='store_true', help='replace an existing output')
    parser.add_argument('--compress', action='store_true', help='zstd-compress the chunks')
    parser.add_argument('--no-diagnostics', action='store_true',
                        help='do not write /diagnostics')
    parser.add_argument('--npz', type=Path, metavar='FILE',
                        help='analysis mode: write no bag, write the outputs as numpy arrays '
                        'to FILE (.npz; keys: see ArraySink); the estimator only')
    parser.add_argument('--smooth', action='store_true',
                        help='also write the Rauch-Tung-Striebel smoothed estimates x(t|T) '
                        '(the whole stream, each segment between resets on its own): on '
                        '/estimate/smoothed, or as estimate/smoothed.* arrays; the estimator '
                        'only')
    parser.add_argument('-q', '--quiet', action='store_true',
                        help='only errors (no progress bar)')
    args = parser.parse_args(argv)
    if args.npz is not None and (args.output is not None or args.filter != 'estimator'
                                 or args.compress):
        parser.error('--npz writes no bag: no output bag, --compress or --filter alignment '
                     'with it')
    if args.npz is not None and (not args.npz.name or args.npz.is_dir()):
        parser.error(f'--npz {args.npz}: a directory; give a file name, e.g. '
                     f'{args.npz / "out.npz"}')
    if args.smooth and args.filter != 'estimator':
        parser.error('--smooth smooths the estimator: not with --filter alignment')
    output = args.output or default_output(args.bag, args.filter)

    def log(line: str) -> None:
        if line.startswith('WARNING') or not args.quiet:
            print(f'{PROG}: {line}', file=sys.stderr if line.startswith('WARNING')
                  else sys.stdout, flush=True)
    if args.npz is not None:
        return _npz_main(args, log)
    try:
        res = replay(args.bag, output, params_file=args.params_file, topic=args.topic,
                     overwrite=args.overwrite, compress=args.compress,
                     diagnostics=not args.no_diagnostics, log=log, filter=args.filter,
                     input_topic=args.input_topic, smooth=args.smooth,
                     progress=not args.quiet)
    except (BagError, ParamsError, BagTypeError, OSError) as exc:
        return error_exit(PROG, exc, args.bag)
    rate = res.read / res.seconds if res.seconds else float('nan')
    statuses = ', '.join(f'{k} {v}' for k, v in sorted(res.statuses.items()))
    if res.input_topic:
        statuses += f'; {res.inputs} inputs on {res.input_topic}'
    log(f'{res.read} messages read, {res.samples} samples on {res.topic} ({statuses}); '
        f'{sum(res.written.values())} output messages; {res.seconds:.2f} s '
        f'({rate:,.0f} msgs/s)')
    log(f'wrote {output}')
    return exit_status(PROG, res.damage, 'input damaged; the output holds what came before')


def _npz_main(args: argparse.Namespace, log: Callable[[str], None]) -> int:
    """Analysis mode (--npz): stream the arrays of replay_arrays into one .npz file."""
    path = args.npz if args.npz.suffix == '.npz' else args.npz.with_name(args.npz.name + '.npz')
    try:
        res = replay_npz(args.bag, path, args.params_file, overwrite=args.overwrite,
                         topic=args.topic, input_topic=args.input_topic,
                         diagnostics=not args.no_diagnostics, log=log, smooth=args.smooth,
                         progress=not args.quiet)
    except (BagError, ParamsError, BagTypeError, OSError) as exc:
        return error_exit(PROG, exc, path)
    log(f'{res.samples} samples on {res.topic} ('
        + ', '.join(f'{k} {v}' for k, v in sorted(res.statuses.items()))
        + f'); {res.seconds:.2f} s')
    log(f'wrote {path}')
    if res.damage is not None:
        print(f'{PROG}: input damaged; the arrays hold what came before: {res.damage}',
              file=sys.stderr)
        return EXIT_DAMAGED
    return 0


def save_npz(path: Path, arrays: dict[str, NDArray]) -> None:
    """Write arrays to path (.npz) whole or not at all: a temporary file, then a rename."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f'.{path.name}.', suffix='.partial', dir=path.parent)
    try:
        with os.fdopen(fd, 'wb') as f:
            np.savez(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def console_main() -> None:
    """Entry point of the console script (Ctrl-C: one line, exit 130)."""
    sys.exit(run_main(PROG, main))


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(console_main)
