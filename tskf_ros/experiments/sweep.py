"""sweep: the estimator (and optionally fit_noise) over many bags x many settings on Dask."""

import argparse
import csv
from dataclasses import dataclass, field
import logging
import os
from pathlib import Path
import sys
from typing import Optional

import numpy as np

from tskf_ros.experiments.bag_analysis import METRICS
from tskf_ros.experiments.fit_noise import EXIT_INTERRUPTED
from tskf_ros.experiments.output import save_figure
from tskf_ros.experiments.sweep_table import Table
from tskf_ros.experiments.sweep_tasks import (build_tasks, find_bags, FIT_COLUMNS, one_line,
                                              parse_setting, run_task, setting_text,
                                              settings_product)
from tskf_ros.messages.estimator_interface import default_parameters, ParamsError

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


def progress_bar(total: int, enabled: bool):
    """Return a tqdm bar on stderr, off when not a terminal or not wanted."""
    from tqdm import tqdm
    return tqdm(total=total, unit='task', disable=not (enabled and sys.stderr.isatty()),
                file=sys.stderr)


def execute(tasks: list, table: Table, *, workers: int, scheduler: Optional[str],
            progress: bool) -> SweepResult:
    """Run the tasks not yet in the table; append each row as it finishes."""
    result = SweepResult()
    todo = [t for t in tasks if t.key not in table.done]
    result.skipped = [t.key for t in tasks if t.key in table.done]
    bar = progress_bar(len(todo), progress)

    def record(row: dict) -> None:
        table.append(row)
        result.evaluated.append(row['key'])
        result.errors += bool(row['error'])
        bar.update(1)

    try:
        if not todo:
            return result
        if workers == 0 and scheduler is None:
            for t in todo:
                record(run_task(t))
            return result
        from dask.distributed import as_completed, Client, LocalCluster
        cluster = None
        if scheduler is None:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   host='127.0.0.1', dashboard_address=None,
                                   silence_logs=logging.ERROR)
            client = Client(cluster)
        else:
            client = Client(scheduler)
        try:
            futures = {client.submit(run_task, t, key=f'sweep-{t.key}', pure=False): t
                       for t in todo}
            for fut in as_completed(futures):
                t = futures[fut]
                try:
                    row = fut.result()
                except Exception as exc:  # noqa: B902 - a lost worker: the row says so
                    row = {'key': t.key, 'bag': t.bag, 'error': one_line(exc)}
                    row.update({name: setting_text(v) for name, v in t.setting.items()})
                record(row)
                fut.release()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
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


def plot(rows: list, sets: list, path: Path) -> Path:
    """Draw the table: per setting, the RMS error and mean NIS of every bag (Agg)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    names = [n for n, _ in sets]
    labels = sorted({', '.join(f'{n}={r[n]}' for n in names) or 'parameter file'
                     for r in rows})
    metrics = [('rms_corrected', 'RMS error, corrected estimate'),
               ('nis_mean', 'mean NIS (1 per measurement dimension when consistent)'),
               ('rejected_gated', 'samples rejected by the gate')]
    fig, axes = plt.subplots(len(metrics), 1, figsize=(max(6, 1.2 * len(labels) + 3), 9),
                             squeeze=False)
    for ax, (col, title) in zip(axes[:, 0], metrics):
        for i, label in enumerate(labels):
            ys = [float(r[col]) for r in rows
                  if (', '.join(f'{n}={r[n]}' for n in names) or 'parameter file') == label
                  and r.get(col) not in ('', None)]
            if ys:
                ax.plot(np.full(len(ys), i), ys, 'o', alpha=0.6)
                ax.plot([i - 0.3, i + 0.3], [np.median(ys)] * 2, 'k-')
        ax.set_title(title, fontsize=9)
        ax.set_xticks(range(len(labels)))
        ax.set_xticklabels(labels, rotation=20, fontsize=8)
        if col == 'rms_corrected' and ax.has_data():
            ax.set_yscale('log')
    fig.suptitle(f'sweep: {len(rows)} rows (bags x settings); line: median over bags',
                 fontsize=10)
    fig.tight_layout()
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
    try:
        defaults = default_parameters()
        sets = [parse_setting(s, defaults) for s in args.sets]
        bags = find_bags(args.bags)
        if not bags:
            raise ValueError(f'no bags found in {" ".join(args.bags)}')
        res = sweep(bags, out=args.out, params_file=args.params_file, sets=sets,
                    workers=args.workers, scheduler=args.scheduler, topic=args.topic,
                    fit=args.fit, resume=args.resume, progress=args.progress)
    except (ValueError, ParamsError, OSError) as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        try:
            with open(args.out, newline='') as f:
                kept = max(sum(1 for _ in csv.reader(f)) - 1, 0)
        except OSError:
            kept = 0
        print(f'{PROG}: interrupted: {kept} rows in {args.out} kept; the same command '
              'resumes', file=sys.stderr)
        return EXIT_INTERRUPTED
    print(f'{PROG}: {len(bags)} bags x {len(settings_product(sets))} settings: '
          f'{len(res.evaluated)} evaluated, {len(res.skipped)} already in {args.out}, '
          f'{res.errors} with errors')
    if args.png:
        try:
            plot(res.rows, sets, args.png)
        except OSError as exc:
            print(f'{PROG}: error: {exc}', file=sys.stderr)
            return 1
    return EXIT_ROW_ERRORS if any(r['error'] for r in res.rows) else 0


def console_main() -> None:
    """Entry point of the console script."""
    sys.exit(main())


if __name__ == '__main__':
    console_main()
