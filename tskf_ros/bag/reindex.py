"""reindex: make a crashed recording a closed, valid bag, as `ros2 bag reindex` does."""

import argparse
import os
from pathlib import Path
import re
import sys
from typing import Optional

from tskf_ros.bag.bag_metadata import write_metadata
from tskf_ros.bag.mcap_file import scan_mcap, seal_mcap
from tskf_ros.bag.outputs import check_outputs
from tskf_ros.bag.reader import BagError, error_exit, EXIT_DAMAGED, MCAP_MAGIC

import yaml

PROG = 'reindex'
EPILOG = """examples:
  reindex /tmp/.run1.partial-k3j9x1      # what `record -o /tmp/run1` left at a SIGKILL
  reindex /tmp/run1                      # a bag whose metadata.yaml is missing or stale

The file is cut after its last whole record and sealed (DataEnd, Footer, magic); nothing
readable is dropped.  Exit status: 0 done; 1 nothing to reindex; 2 usage; 3 the file is
damaged before its end (metadata.yaml lists the messages up to the damage)."""
PARTIAL = re.compile(r'^\.(?P<name>.+)\.partial-[^/]+$')


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


def mcap_file(bagdir: Path) -> Path:
    """Return the one MCAP file of a bag directory."""
    files = sorted(p for p in bagdir.glob('*.mcap') if p.is_file() and not p.is_symlink())
    if len(files) != 1:
        raise ReindexError(f'{bagdir}: {"no" if not files else len(files)} MCAP files '
                           '(reindex takes a bag with one)')
    size = files[0].stat().st_size
    if size == 0:
        raise ReindexError(f'{files[0]}: empty file (0 bytes): nothing was recorded')
    return files[0]


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


def reindex(path: Path, output: Optional[Path] = None) -> tuple[Path, int, Optional[object]]:
    """Repair a crashed recording; return (the bag, messages in it, damage or None)."""
    bagdir, target = locate(Path(path))
    if output is not None:
        target = Path(output)
        if target.resolve() != bagdir.resolve():
            check_outputs([target], [bagdir])
    mcap = mcap_file(bagdir)
    if target.resolve() != bagdir.resolve() and (target.exists() or target.is_symlink()):
        raise ReindexError(f'{target}: exists already, not overwriting (give -o OUTPUT)')
    if not target.name or target.name in ('.', '..'):
        raise ReindexError(f'{target}: not a usable bag name')
    custom = {}
    meta = bagdir / 'metadata.yaml'
    if meta.is_file():
        try:
            old = yaml.safe_load(meta.read_text())['rosbag2_bagfile_information']
            custom = {str(k): str(v) for k, v in (old.get('custom_data') or {}).items()}
        except (OSError, yaml.YAMLError, KeyError, TypeError, AttributeError, ValueError):
            custom = {}
    note = 'metadata.yaml rewritten from the closed MCAP file'
    if not is_closed(mcap):
        size = mcap.stat().st_size
        kept, cut = seal_mcap(mcap)
        note = (f'sealed after {kept} bytes' + (f' (cut {size - kept} bytes of a record cut '
                                                'short)' if cut else ''))
    stats = scan_mcap(mcap)
    damage = stats.damage
    custom['tskf_ros.reindexed'] = note
    if damage is not None:
        custom['tskf_ros.reindex_damage'] = str(damage)
    write_metadata(bagdir, mcap, stats=stats, custom_data=custom)
    if target.resolve() != bagdir.resolve():
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(bagdir, target)
        partial = bagdir.parent
        if PARTIAL.match(partial.name):
            try:
                partial.rmdir()     # only if empty: nothing else is ever deleted
            except OSError:
                pass
    return target, sum(stats.counts.values()), damage


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
    console_main()
