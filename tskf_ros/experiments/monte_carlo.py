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
The LED Monte Carlo's points on every core: split into parts, batched, joined in order.

A point is one aligner on one link for some runs.  Its runs are split into parts of at
most PART_RUNS (part k > 0 draws from the generator [seed, k], so the numbers of a seed
depend on nothing else), the parts of points of one kind (Point.kind: they differ in
runs, part, noise, dropout and drift rate only) run side by side on one aligner
(led.simulate_blocks), at most BATCH_RUNS a task, and the tasks on a process pool.  What
each experiment builds and measures is its Experiment; the results depend on neither the
workers, nor the batches, nor the order the tasks end in.
"""

from concurrent.futures import ProcessPoolExecutor
import dataclasses
import functools
from typing import Any, Iterator, Optional, Protocol, Sequence

import numpy as np

from tskf_ros import led

__all__ = ['BATCH_RUNS', 'Experiment', 'PART_RUNS', 'Point', 'SchedulerError', 'batches',
           'dask_client', 'parts', 'run_batch', 'run_points']

# runs drawn from one generator: a point of more runs is split into parts, part k > 0
# drawing from the generator [seed, k] (the numbers of a seed do not depend on anything else)
PART_RUNS = 1000
# runs simulated side by side by one task (the parts, and the levels of a sweep, of one
# algorithm): memory is bounded by this, not by the runs of a point
BATCH_RUNS = 4000


@dataclasses.dataclass(frozen=True)
class Point:
    """One algorithm on one link (or part of its runs: `part`)."""

    name: str
    runs: int
    link: led.TrackingLinkConfig
    seed: int
    response: led.IncidenceResponse
    ekf: led.EKFConfig
    clip: bool
    controller: str
    part: int = 0       # part k > 0 of a point's runs draws from the generator [seed, k]
    lqg: Optional[led.LQGConfig] = None     # the LQG controller's (None: LQGConfig(dt))

    def kind(self) -> 'Point':
        """Return what points run side by side share: all but runs, part, noise, dropout, beta."""
        return dataclasses.replace(self, runs=0, part=0, link=dataclasses.replace(
            self.link, noise=0.0, dropout=0.0, beta=0.0))


class Experiment(Protocol):
    """What a Monte Carlo simulates and measures (a module-level object: it is pickled)."""

    keep: tuple[str, ...]       # the Trajectory fields the measures read

    def build(self, points: Sequence[Point], runs: int) -> led.Aligner:
        """Return the aligner of points of one kind side by side (runs in all)."""

    def finish(self, aligner: led.Aligner) -> Any:
        """Return what the measures read of the aligner after the simulation."""

    def measure(self, traj: led.Trajectory, p: Point, end: Any, cols: slice) -> Any:
        """Return the measures of point p: traj is its columns `cols`; end: finish's."""

    def join(self, parts: list) -> Any:
        """Return the measures of the parts of a point, in order, as of one simulation."""


class SchedulerError(RuntimeError):
    """The Dask scheduler given cannot be used (not installed, or not reached)."""


def parts(p: Point, size: int) -> list[Point]:
    """Split a point's runs into parts of at most `size` runs (the first draws the seed's)."""
    return [dataclasses.replace(p, runs=min(size, p.runs - start), part=k)
            for k, start in enumerate(range(0, p.runs, size))]


def batches(points: Sequence[Point], size: int = BATCH_RUNS) -> list[list[int]]:
    """
    Group points (parts) into the tasks of run_batch: indices, at most `size` runs each.

    A task holds points of one kind (Point.kind), in order; at least one point.  The
    tasks take the kinds in turn (the first task of each, then the second, ...), so that
    the workers' last tasks are of every kind, not all of the last one.
    """
    kinds: dict[Point, list[list[int]]] = {}
    for i, p in enumerate(points):
        tasks = kinds.setdefault(p.kind(), [[]])
        if tasks[-1] and sum(points[j].runs for j in tasks[-1]) + p.runs > size:
            tasks.append([])
        tasks[-1].append(i)
    rounds = max(len(tasks) for tasks in kinds.values())
    return [tasks[k] for k in range(rounds) for tasks in kinds.values() if k < len(tasks)]


@functools.lru_cache(maxsize=4)
def _draws(seed: int, part: int, runs: int,
           link: led.TrackingLinkConfig) -> led.Disturbances:
    """
    Return the random numbers of a part (kept: every algorithm and level draws the same).

    Read-only: the simulations share them.
    """
    rng = np.random.default_rng(seed if part == 0 else [seed, part])
    noise = led.draw_disturbances(link, rng, runs)
    for field in dataclasses.fields(noise):
        getattr(noise, field.name).setflags(write=False)
    return noise


def run_batch(points: Sequence[Point], experiment: Experiment) -> list:
    """
    Simulate points of one kind side by side (one aligner); return the measures of each.

    Each point draws its numbers as it would alone: common random numbers, the same draws
    for every algorithm and level of a part.  Each run is, number for number, what the
    point gives alone (led.simulate_blocks).
    """
    first = points[0]
    if any(p.kind() != first.kind() for p in points):
        raise ValueError('run_batch simulates points of one kind (Point.kind) side by side')
    blocks = [led.Block(p.link, _draws(p.seed, p.part, p.runs, first.kind().link))
              for p in points]
    aligner = experiment.build(points, sum(p.runs for p in points))
    traj = led.simulate_blocks(aligner, blocks, first.response, keep=experiment.keep)
    end = experiment.finish(aligner)
    out = []
    start = 0
    for p in points:
        cols = slice(start, start + p.runs)
        start += p.runs
        part = led.Trajectory(t=traj.t, phi=traj.phi[:, cols], x2=traj.x2[:, cols],
                              x1=traj.x1[:, cols], clean=traj.clean[:, cols], z=traj.z[:, cols],
                              command=traj.command[:, cols])
        out.append(experiment.measure(part, p, end, cols))
    return out


def run_points(points: Sequence[Point], workers: int, experiment: Experiment,
               part_runs: Optional[int] = None, batch_runs: Optional[int] = None,
               scheduler: Optional[str] = None) -> Iterator[Any]:
    """
    Yield the measures of each point, in order, computed on `workers` processes.

    scheduler: the address of a Dask scheduler (e.g. tcp://host:8786), whose workers run
    the tasks instead (they need this package); raises SchedulerError if it cannot be used.

    Each point runs in parts of at most part_runs runs (PART_RUNS), and the parts of points
    of one kind side by side, at most batch_runs runs (BATCH_RUNS) a task; the parts are
    joined in order (experiment.join): the results depend on neither the workers, nor the
    batches, nor the order the tasks end in.
    """
    split = [parts(p, part_runs or PART_RUNS) for p in points]
    flat = [q for point in split for q in point]
    tasks = batches(flat, batch_runs or BATCH_RUNS)
    work = [[flat[i] for i in task] for task in tasks]
    task = functools.partial(run_batch, experiment=experiment)
    if scheduler is not None:
        with dask_client(scheduler) as client:
            futures = client.map(task, work, pure=False)
            yield from _joined(split, tasks, (f.result() for f in futures), experiment)
        return
    if workers <= 1 or len(work) <= 1:
        yield from _joined(split, tasks, map(task, work), experiment)
        return
    with ProcessPoolExecutor(max_workers=min(workers, len(work))) as pool:
        yield from _joined(split, tasks, pool.map(task, work), experiment)


def dask_client(address: str) -> Any:
    """Return a dask.distributed Client of the scheduler at address (or SchedulerError)."""
    try:
        from dask.distributed import Client
    except ImportError:
        raise SchedulerError('--scheduler needs dask.distributed (the analysis extra: '
                             "pip install '.[analysis]')") from None
    try:
        return Client(address, timeout=10)
    except (OSError, TimeoutError, ValueError) as exc:
        raise SchedulerError(f'cannot use the Dask scheduler at {address}: {exc}') from None


def _joined(split: list[list[Point]], tasks: list[list[int]], done: Iterator[list],
            experiment: Experiment) -> Iterator[Any]:
    """Join the parts of each point in order, as the tasks (indices into the parts) end."""
    got: dict[int, Any] = {}
    first = 0                       # index of the first part of the next point to yield
    point = 0
    for task, results in zip(tasks, done):
        got.update(zip(task, results))
        while point < len(split) and all(first + j in got for j in range(len(split[point]))):
            yield experiment.join([got.pop(first + j) for j in range(len(split[point]))])
            first += len(split[point])
            point += 1
