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

"""reindex: make a crashed recording a closed, valid bag, as `ros2 bag reindex` does."""

import argparse
import os
from pathlib import Path
import re
import sys
from typing import Optional

from tskf_ros.bag.bag_errors import BagError, Damage, error_exit, EXIT_DAMAGED, resolved
from tskf_ros.bag.bag_metadata import file_metadata, merge_metadata, write_yaml
from tskf_ros.bag.mcap_file import scan_mcap, seal_mcap
from tskf_ros.bag.outputs import check_outputs
from tskf_ros.bag.reader import MCAP_MAGIC
from tskf_ros.bag.split_bag import adopt_split_files, RESERVE

import yaml

PROG = 'reindex'
EPILOG = """examples:
  reindex /tmp/.run1.partial-k3j9x1      # what `record -o /tmp/run1` left at a SIGKILL
  reindex /tmp/run1                      # a bag whose metadata.yaml is missing or stale

A file that was never closed is cut after its last whole record and sealed (DataEnd with
the data section's CRC, Footer, magic); nothing readable is dropped.  A bag of several
files (NAME_0.mcap, NAME_1.mcap, ..., as rosbag2 names them) gets one metadata.yaml that
lists them in that order; in the .partial directory of a split recording, the file that
was being written when it stopped (in a directory of its own) is taken in too.  Exit
status: 0 done; 1 nothing to reindex; 2 usage; 3 a file is damaged before its end
(metadata.yaml lists the messages up to the damage)."""
PARTIAL = re.compile(r'^\.(?P<name>.+)\.partial-[^/]+$')
# a file of a bag of several, as rosbag2's reindexer matches them: NAME_<n>.<ext>
NUMBERED = re.compile(r'.+_(\d+)\.mcap')


class ReindexError(BagError):
    """Nothing that reindex can repair (no MCAP file, an empty one, an existing output)."""


def locate(path: Path) -> tuple[Path, Path]:
    """Return (the bag directory holding the MCAP file, the bag directory to produce)."""
    if not path.exists():
        raise ReindexError(f'{path}: no such directory')
    if not path.is_dir():
        raise ReindexError(f'{path}: not a directory (give the bag directory or the '
                           '.partial directory the recorder left)')
    match = PARTIAL.match(path.name)
    if match:
        inner = path / match['name']
        if not inner.is_dir():
            raise ReindexError(f'{path}: no {match["name"]} directory inside: not a '
                               'recording')
        return inner, path.parent / match['name']
    match = PARTIAL.match(path.parent.name)
    if match and match['name'] == path.name:
        return path, path.parent.parent / path.name
    return path, path


def mcap_files(bagdir: Path) -> list[Path]:
    """
    Return the MCAP files of a bag directory in their order, as rosbag2's reindex finds them.

    rosbag2 takes the files named NAME_<n>.<ext> in the order of n; a bag of one file may
    also be NAME.mcap (as this package writes it).  Empty files are left out (they hold no
    record), unless there is nothing else.
    """
    files = [p for p in bagdir.glob('*.mcap') if p.is_file() and not p.is_symlink()]
    numbered = sorted((int(m[1]), p) for p in files if (m := NUMBERED.fullmatch(p.name)))
    if numbered:
        files = [p for _, p in numbered]
    elif len(files) > 1:
        raise ReindexError(f'{bagdir}: {len(files)} MCAP files not named NAME_<n>.mcap: '
                           'their order is unknown')
    if not files:
        raise ReindexError(f'{bagdir}: no MCAP file')
    kept = [p for p in files if p.stat().st_size > 0]
    if not kept:
        raise ReindexError(f'{files[0]}: empty file (0 bytes): nothing was recorded')
    return kept


def is_closed(path: Path) -> bool:
    """Say whether an MCAP file ends with a Footer record and the magic."""
    size = path.stat().st_size
    if size < 2 * len(MCAP_MAGIC) + 29:
        return False
    with path.open('rb') as f:
        f.seek(size - len(MCAP_MAGIC) - 29)
        tail = f.read()
    footer = bytes([0x02]) + (20).to_bytes(8, 'little')
    return tail[-8:] == MCAP_MAGIC and tail[:9] == footer


def reindex(path: Path, output: Optional[Path] = None) -> tuple[Path, int, Optional[Damage]]:
    """Repair a crashed recording; return (the bag, messages in it, the first damage or None)."""
    bagdir, target = locate(Path(path))
    if output is not None:
        target = Path(output)
    if PARTIAL.match(bagdir.parent.name):
        # a split recording: the file in progress may still be in a directory of its own
        adopt_split_files(bagdir.parent, bagdir)
    files = mcap_files(bagdir)
    same = resolved(target) == resolved(bagdir)
    if output is not None and not same:
        check_outputs([target], [bagdir])
    if not same and (target.exists() or target.is_symlink()):
        raise ReindexError(f'{target}: exists already, not overwriting (give -o OUTPUT)')
    if not target.name or target.name in ('.', '..'):
        raise ReindexError(f'{target}: not a usable bag name')
    custom = _old_custom_data(bagdir / 'metadata.yaml')
    infos, notes, damage = [], [], None
    for mcap in files:
        note = 'rewritten from the closed file'
        if not is_closed(mcap):
            size = mcap.stat().st_size
            kept, cut = seal_mcap(mcap)
            note = (f'sealed after {kept} bytes' + (f' (cut {size - kept} bytes of a record '
                                                    'cut short)' if cut else ''))
        stats = scan_mcap(mcap)
        damage = damage or stats.damage
        infos.append(file_metadata(mcap, stats=stats))
        notes.append(f'{mcap.name}: {note}')
    custom['tskf_ros.reindexed'] = ('metadata.yaml rewritten from the MCAP files; '
                                    + '; '.join(notes))
    if damage is not None:
        custom['tskf_ros.reindex_damage'] = str(damage)
    info = merge_metadata(infos, custom)
    write_yaml(bagdir / 'metadata.yaml', {'rosbag2_bagfile_information': info})
    if not same:
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(bagdir, target)
        partial = bagdir.parent
        if PARTIAL.match(partial.name):
            (partial / RESERVE).unlink(missing_ok=True)     # the recorder's spare room
            try:
                partial.rmdir()     # only if empty: nothing else is ever deleted
            except OSError:
                pass
    return target, int(info['message_count']), damage


def _old_custom_data(meta: Path) -> dict:
    """Return the custom_data of an earlier metadata.yaml ({} if there is none readable)."""
    if not meta.is_file():
        return {}
    try:
        old = yaml.safe_load(meta.read_text())['rosbag2_bagfile_information']
        return {str(k): str(v) for k, v in (old.get('custom_data') or {}).items()}
    except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError, ValueError):
        return {}


def main(argv: Optional[list] = None) -> int:
    """Run the command line; return the exit status."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Turn a crashed recording (the .partial directory record '
        'left, or a bag directory without a valid metadata.yaml) into a valid bag.',
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('path', type=Path, help='.<name>.partial-XXXX directory or bag '
                        'directory')
    parser.add_argument('-o', '--output', type=Path, help='bag directory to produce '
                        '(default: <name> next to a .partial directory; a bag in place)')
    args = parser.parse_args(argv)
    try:
        bag, count, damage = reindex(args.path, args.output)
    except (BagError, OSError) as exc:
        return error_exit(PROG, exc, args.path)
    print(f'{PROG}: wrote {bag} ({count} messages)')
    if damage is not None:
        print(f'{PROG}: damaged: {damage}', file=sys.stderr)
        return EXIT_DAMAGED
    return 0


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(console_main)
