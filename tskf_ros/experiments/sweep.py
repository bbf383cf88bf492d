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

"""sweep: the estimator (and optionally fit_noise) over many bags x many settings on Dask."""

import argparse
import csv
from dataclasses import dataclass, field
import os
from pathlib import Path
import sys
from typing import Optional

import numpy as np

from tskf_ros.bag.outputs import check_outputs
from tskf_ros.bag.reader import BagError, error_exit
from tskf_ros.core.optional_dependencies import (EXIT_MISSING_DEPENDENCY, MissingDependency,
                                                 require)
from tskf_ros.experiments.bag_analysis import METRICS
from tskf_ros.experiments.fit_noise import EXIT_INTERRUPTED
from tskf_ros.experiments.output import save_figure
from tskf_ros.experiments.sweep_cluster import close, local_cluster, quiet_dask
from tskf_ros.experiments.sweep_progress import (run_task_reporting, SweepBar, TaskProgress,
                                                 terminal, TOPIC)
from tskf_ros.experiments.sweep_table import Table
from tskf_ros.experiments.sweep_tasks import (build_tasks, find_bags, FIT_COLUMNS, one_line,
                                              parse_setting, run_task, setting_text,
                                              settings_product)
from tskf_ros.messages.estimator_interface import default_parameters, ParamsError
from tskf_ros.tools.console import SigintFlag, SigintHeld

PROG = 'sweep'
EXIT_ROW_ERRORS = 5
# a LocalCluster larger than this is a typo, not a plan (use --scheduler for a big cluster)
MAX_WORKERS = 256


@dataclass
class SweepResult:
    """What a sweep did: the keys evaluated now, skipped (already in the CSV), and errors."""

    evaluated: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    errors: int = 0
    rows: list = field(default_factory=list)


def execute(tasks: list, table: Table, *, workers: int, scheduler: Optional[str],
            progress: bool) -> SweepResult:
    """
    Run the tasks not yet in the table; append each row as it finishes.

    progress: a bar of the messages read (sweep_progress), on a terminal.
    """
    result = SweepResult()
    todo = [t for t in tasks if t.key not in table.done]
    result.skipped = [t.key for t in tasks if t.key in table.done]
    bar = SweepBar(todo, progress and terminal())

    def record(row: dict) -> None:
        table.append(row)
        result.evaluated.append(row['key'])
        result.errors += bool(row['error'])
        bar.done(row['key'])

    try:
        if not todo:
            return result
        if workers == 0 and scheduler is None:
            for t in todo:
                record(run_task(t, TaskProgress(t.key, bar.receive) if bar.enabled else None))
            return result
        from dask.distributed import as_completed, Client
        # a Ctrl-C raised where it is swallowed (a finaliser, a callback of distributed's)
        # would let the loop finish: remember it, and stop at the next row.  Dask is
        # silenced in the handler itself: the interrupt reaches distributed's sync(), whose
        # cancel callback runs at once on the event loop's thread and can log an error
        # (a NameError of distributed's own) before this thread gets to the except below
        interrupted = SigintFlag(first=quiet_dask)
        cluster = client = None
        futures: dict = {}
        try:
            if scheduler is None:
                cluster = local_cluster(workers)
                # a client cut short while it connects would be left half made
                with SigintHeld() as held:
                    client = Client(cluster)
                if held.came:
                    raise KeyboardInterrupt
            else:
                client = Client(scheduler)
            if bar.enabled:
                # the workers' reports come on the client's event loop, as (time, report)
                client.subscribe_topic(TOPIC, lambda event: bar.receive(event[1]))
            task_function = run_task_reporting if bar.enabled else run_task
            futures = {client.submit(task_function, t, key=f'sweep-{t.key}', pure=False): t
                       for t in todo}
            for fut in as_completed(futures):
                if interrupted.is_set():
                    raise KeyboardInterrupt
                t = futures[fut]
                try:
                    row = fut.result()
                except Exception as exc:  # noqa: B902 - a lost worker: the row says so
                    row = {'key': t.key, 'bag': t.bag, 'error': one_line(exc)}
                    row.update({name: setting_text(v) for name, v in t.setting.items()})
                record(row)
                fut.release()
        except KeyboardInterrupt:
            # the workers are stopped now: what they log while going is not for the user
            quiet_dask()
            raise
        finally:
            interrupted.restore()
            if close(client, cluster, futures=list(futures)):
                raise KeyboardInterrupt     # a Ctrl-C while they closed: said as one
    finally:
        bar.close()
    return result


def sweep(bags: list, *, out: Path, params_file: Optional[Path] = None, sets: list = (),
          workers: int = 1, scheduler: Optional[str] = None, topic: Optional[str] = None,
          fit: bool = False, resume: bool = True, progress: bool = False) -> SweepResult:
    """Run the sweep; return what it did (the rows are in `out` and in result.rows)."""
    sets = list(sets)
    columns = (['key', 'bag'] + [n for n, _ in sets] + list(METRICS)
               + (FIT_COLUMNS if fit else []) + ['seconds', 'error'])
    tasks = build_tasks(bags, params_file, sets, topic=topic, fit=fit)
    table = Table(out, columns, resume)
    try:
        result = execute(tasks, table, workers=workers, scheduler=scheduler, progress=progress)
    finally:
        table.close()
    wanted = {t.key for t in tasks}
    result.rows = [r for r in table.rows if r['key'] in wanted]
    return result


def bag_labels(bags: list) -> dict:
    """Return {bag: short label}: the bag's name, with its parent if two bags share it."""
    names = [Path(b).name for b in bags]
    return {b: (str(Path(*Path(b).parts[-2:])) if names.count(Path(b).name) > 1
                else Path(b).name) for b in bags}


def plot(rows: list, sets: list, path: Path) -> Path:
    """
    Draw the table: per setting, each bag's RMS error, mean NIS (95% band) and gated count.

    One colour and marker per bag (the legend); rows with an error are not drawn, and the
    footnote names them.  The gate panel is left out when no row gated a sample.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullFormatter
    names = [n for n, _ in sets]

    def label_of(r: dict) -> str:
        return ', '.join(f'{n}={r[n]}' for n in names) or 'parameter file'

    def number(r: dict, col: str) -> float:
        try:
            return float(r.get(col, ''))
        except (TypeError, ValueError):
            return float('nan')

    good = [r for r in rows if not r.get('error')]
    failed = sorted({r['bag'] for r in rows if r.get('error')})
    labels = sorted({label_of(r) for r in rows})
    bags = sorted({r['bag'] for r in good})
    short = bag_labels(sorted({r['bag'] for r in rows}))
    gated = any(number(r, 'rejected_gated') > 0 for r in good)
    panels = [('rms_corrected', 'RMS error of the corrected estimate against the truth',
               'RMS error (state units)'),
              ('nis_mean', 'mean NIS, with the 95% band of each bag (chi-square)',
               'mean NIS')]
    if gated:
        panels.append(('rejected_gated', 'samples rejected by the innovation gate',
                       'samples'))
    fig, axes = plt.subplots(len(panels), 1, squeeze=False, sharex=True,
                             figsize=(max(7.0, 1.3 * len(labels) + 4.0), 3.2 * len(panels)))
    markers = 'osD^v<>pP*Xh'
    width = 0.4
    offsets = np.linspace(-width / 2, width / 2, len(bags)) if len(bags) > 1 else [0.0]
    for ax, (col, title, ylabel) in zip(axes[:, 0], panels):
        for b, (bag, dx) in enumerate(zip(bags, offsets)):
            colour = plt.cm.tab10(b % 10)
            pts = [(labels.index(label_of(r)) + dx, number(r, col), r) for r in good
                   if r['bag'] == bag and np.isfinite(number(r, col))]
            if not pts:
                continue
            xs, ys = [p[0] for p in pts], [p[1] for p in pts]
            if col == 'nis_mean':
                lo = [number(p[2], 'nis_band_lo') for p in pts]
                hi = [number(p[2], 'nis_band_hi') for p in pts]
                ax.vlines(xs, lo, hi, colors=[colour], alpha=0.35, linewidth=9,
                          label='95% band of the mean NIS' if b == 0 else None)
            ax.plot(xs, ys, linestyle='none', marker=markers[b % len(markers)],
                    color=colour, label=short[bag])
        ax.set_title(title, fontsize=9)
        ax.set_ylabel(ylabel, fontsize=8)
        if col in ('rms_corrected', 'nis_mean') and ax.has_data():
            ax.set_yscale('log')
            lo, hi = ax.get_ylim()
            # over decades: 1-2-5 ticks; within about one: evenly spaced numbers
            ax.yaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0))
                                       if hi > 30 * lo else MaxNLocator(nbins=6))
            ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f'{v:g}'))
            ax.yaxis.set_minor_formatter(NullFormatter())
        elif ax.has_data():
            ax.set_ylim(bottom=0)
            ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(True, which='major', axis='y', alpha=0.3)
    axes[-1, 0].set_xticks(range(len(labels)))
    axes[-1, 0].set_xticklabels(labels, rotation=20, ha='right', fontsize=8)
    axes[-1, 0].set_xlabel('setting (--set)' if names else 'the parameter file')
    if bags:
        axes[0, 0].legend(fontsize=7, loc='center left', bbox_to_anchor=(1.01, 0.5),
                          title='bag', title_fontsize=7)
        handles, texts = axes[1, 0].get_legend_handles_labels()
        band = [(h, t) for h, t in zip(handles, texts) if t.startswith('95%')]
        if band:
            axes[1, 0].legend(*zip(*band), fontsize=7, loc='center left',
                              bbox_to_anchor=(1.01, 0.5))
    notes = []
    if not gated:
        notes.append('no sample was rejected by the innovation gate in any row')
    if failed:
        notes.append('not drawn (error rows, see the CSV): '
                     + ', '.join(short[b] for b in failed))
    fig.suptitle(f'sweep: {len(rows)} rows ({len(bags) + len(failed)} bags x '
                 f'{len(labels)} settings)', fontsize=10)
    if notes:
        fig.text(0.01, 0.005, '; '.join(notes), fontsize=7, va='bottom')
    fig.tight_layout(rect=(0, 0.03 if notes else 0, 1, 0.97))
    return save_figure(fig, path)


def main(argv: Optional[list] = None) -> int:
    """Run the command line; return the exit status."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Run the time-scale estimator over bags x settings on Dask and '
        'write one CSV row per bag and setting.')
    parser.add_argument('--bags', nargs='+', required=True,
                        help='bags, directories holding bags (searched recursively) or glob '
                        "patterns (quote them; '**' is recursive)")
    parser.add_argument('--params-file', type=Path, help='estimator parameters (default: the '
                        "node's defaults); each --set overrides one of them")
    parser.add_argument('--set', dest='sets', action='append', default=[],
                        metavar='NAME=V1,V2', help='a parameter and its values; the sweep '
                        'runs every combination of all --set (matrices: space-separated '
                        "numbers, e.g. 'R=1 0 0 1')")
    parser.add_argument('--topic', help='measurement topic (default /received_power, else the '
                        'only stamped scalar topic of each bag)')
    parser.add_argument('--workers', type=int, default=os.cpu_count() or 1,
                        help='LocalCluster worker processes (default: one per core; 0: run '
                        'in this process without Dask)')
    parser.add_argument('--scheduler', help='address of an existing Dask scheduler, e.g. '
                        'tcp://host:8786 (then --workers is ignored)')
    parser.add_argument('--out', type=Path, required=True, help='the CSV table')
    parser.add_argument('--png', type=Path, help='also draw the table into this PNG')
    parser.add_argument('--fit', action='store_true',
                        help='also fit Q and R to each bag (fit_noise) under each setting')
    parser.add_argument('--no-resume', dest='resume', action='store_false',
                        help='start a new table instead of skipping the rows already in --out')
    parser.add_argument('--no-progress', dest='progress', action='store_false',
                        help='no progress bar (it is off anyway when stderr is not a terminal)')
    args = parser.parse_args(argv)
    if not 0 <= args.workers <= MAX_WORKERS:
        parser.error(f'--workers must be between 0 and {MAX_WORKERS}')
    if args.workers or args.scheduler:
        try:
            require('distributed', 'sweep --workers/--scheduler (a Dask cluster)')
        except MissingDependency as exc:
            print(f'{PROG}: error: {exc}; --workers 0 runs without Dask', file=sys.stderr)
            return EXIT_MISSING_DEPENDENCY
    try:
        defaults = default_parameters()
        sets = [parse_setting(s, defaults) for s in args.sets]
        bags = find_bags(args.bags)
        if not bags:
            raise ValueError(f'no bags found in {" ".join(args.bags)}')
        if args.png and args.png.resolve() == args.out.resolve():
            raise ValueError('--png and --out are the same file')
        check_outputs([args.out, args.png], bags)
        res = sweep(bags, out=args.out, params_file=args.params_file, sets=sets,
                    workers=args.workers, scheduler=args.scheduler, topic=args.topic,
                    fit=args.fit, resume=args.resume, progress=args.progress)
    except (ValueError, ParamsError, BagError) as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return 1
    except OSError as exc:
        return error_exit(PROG, exc, args.out)
    except KeyboardInterrupt:
        return interrupted(args.out)
    print(f'{PROG}: {len(bags)} bags x {len(settings_product(sets))} settings: '
          f'{len(res.evaluated)} evaluated, {len(res.skipped)} already in {args.out}, '
          f'{res.errors} with errors')
    if args.png:
        try:
            plot(res.rows, sets, args.png)
        except OSError as exc:
            print(f'{PROG}: error: {exc}', file=sys.stderr)
            return 1
        except KeyboardInterrupt:       # the figure goes through a temporary file
            return interrupted(args.out)
    return EXIT_ROW_ERRORS if any(r['error'] for r in res.rows) else 0


def interrupted(out: Path) -> int:
    """Say in one line what a Ctrl-C left: the whole rows of the table, if it exists."""
    try:
        with open(out, newline='') as f:
            kept = max(sum(1 for _ in csv.reader(f)) - 1, 0)
    except FileNotFoundError:
        print(f'{PROG}: interrupted: nothing written', file=sys.stderr)
        return EXIT_INTERRUPTED
    except OSError:
        kept = 0
    print(f'{PROG}: interrupted: {kept} rows in {out} kept; the same command resumes',
          file=sys.stderr)
    return EXIT_INTERRUPTED


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    from tskf_ros.tools.console import run_as_main
    run_as_main(console_main)
