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

"""The sweep's Dask LocalCluster: started and closed whole, Ctrl-C in any phase, quiet."""

import logging
from typing import Any, Sequence

from tskf_ros.tools.console import SigintHeld

__all__ = ['close', 'local_cluster', 'quiet_dask']


def close(client: Any, cluster: Any, futures: Sequence = ()) -> bool:
    """
    Close a Dask client and cluster (None: none) whole; return whether a Ctrl-C came.

    The futures not done are cancelled first, so that each worker stops once its running
    task ends.  A Ctrl-C is held meanwhile (SigintHeld): one that cut the close short
    would leave the worker processes to be killed at exit, their semaphores leaked (the
    resource tracker's warning) and their heartbeats failing (tracebacks in their logs).
    """
    with SigintHeld() as held:
        if client is not None:
            if futures:
                client.cancel([f for f in futures if not f.done()])
            client.close()
        if cluster is not None:
            cluster.close()
    return held.came


def local_cluster(workers: int):
    """
    Start a LocalCluster of `workers` processes that do not take SIGINT themselves.

    Ctrl-C in a terminal goes to every process of the foreground group: each worker would
    print its own KeyboardInterrupt traceback.  The cluster starts with SIGINT held
    (SigintHeld), so that its threads, and the worker processes they start, inherit a
    mask that holds it for good; this process takes Ctrl-C and stops them.  A Ctrl-C
    while the cluster starts is not lost: once it has started it is closed, and
    KeyboardInterrupt raised.
    """
    import multiprocessing

    from dask.distributed import LocalCluster
    # multiprocessing's resource tracker started now, from this thread: the thread that
    # starts it unblocks SIGINT for itself (the standard library's guard for the tracker),
    # which the cluster's event loop would pass on to the threads that start the workers
    multiprocessing.get_context('spawn').Lock()
    cluster = None
    try:
        with SigintHeld() as held:
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                   host='127.0.0.1', dashboard_address=None,
                                   # with no dashboard the scheduler still serves HTTP
                                   # (health routes), on 8787 unless told: a port of its
                                   # own on loopback, so that two sweeps do not warn "Port
                                   # 8787 is already in use"
                                   scheduler_kwargs={'dashboard_address': '127.0.0.1:0'},
                                   # the workers' logs: a task's error comes back as
                                   # its row's; a worker stopped mid-task after a Ctrl-C
                                   # logs its failed heartbeats as errors
                                   silence_logs=logging.CRITICAL)
        if held.came:
            raise KeyboardInterrupt
    except KeyboardInterrupt:
        quiet_dask()
        close(None, cluster)
        raise
    return cluster


def quiet_dask() -> None:
    """
    Silence distributed's loggers (a shutdown after Ctrl-C logs lost connections).

    Every logger under distributed, tornado and asyncio: distributed's logging config
    gives some of them a level of their own (tornado.application: ERROR), which a level
    on the parent does not override.
    """
    families = ('distributed', 'tornado', 'asyncio')
    names = [*families, *(name for name, logger in list(logging.root.manager.loggerDict.items())
                          if isinstance(logger, logging.Logger))]
    for name in names:
        if name.split('.')[0] in families:
            logging.getLogger(name).setLevel(logging.CRITICAL + 1)
