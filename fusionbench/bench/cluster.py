"""Monte Carlo on a Dask cluster: ``fusionbench run`` with ``--scheduler ADDRESS`` or ``--cluster local[:N]``.

The runners split a Monte Carlo into batches of runs and hand them to joblib; here joblib's Dask backend
(``joblib.parallel_config(backend="dask")``) sends those batches to the workers of a ``dask.distributed`` cluster
instead of local processes. Run k of a seed draws from its own ``SeedSequence`` whatever batch or worker it lands
in, so a cluster gives the numbers of ``--jobs 1`` bit for bit. The workers import the installed fusionbench (the
compiled kernels are module-level functions, cached per user on each machine); every machine needs the same
fusionbench and library versions.

``dask[distributed]`` is the optional extra ``[cluster]`` (``pip install 'fusionbench[cluster]'``).
"""

from __future__ import annotations

import contextlib
import os
import re

__all__ = ["parse_cluster", "connect"]

_LOCAL = re.compile(r"^local(?::(\d+))?$")


def parse_cluster(text):
    """``local`` or ``local:N`` (N >= 1 worker processes) as the number of workers (None: one per core).

    Raises
    ------
    ValueError
        One line saying what was expected and found.
    """
    m = _LOCAL.match(str(text))
    if not m or (m.group(1) is not None and int(m.group(1)) < 1):
        raise ValueError(f"--cluster: expected local or local:N (N >= 1 worker processes), found {text!r}")
    return None if m.group(1) is None else int(m.group(1))


def _distributed():
    try:
        import distributed
    except ImportError:
        raise ValueError("--scheduler and --cluster need Dask's distributed scheduler: pip install "
                         "'fusionbench[cluster]' (dask[distributed])") from None
    return distributed


def _probe(scheduler, timeout_s):
    """One TCP connection to a ``tcp://host:port`` address: a refusal (nothing listens there) is reported at once,
    where distributed's client would retry until its timeout. Other schemes are left to distributed."""
    import socket
    from urllib.parse import urlsplit

    parts = urlsplit(scheduler)
    try:
        host, port = parts.hostname, parts.port
    except ValueError:  # a port that is not a number: distributed names it
        return
    if parts.scheme != "tcp" or host is None or port is None:
        return
    try:
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError as exc:
        raise ValueError(f"--scheduler {scheduler}: no Dask scheduler answered ({type(exc).__name__}: "
                         f"{exc.strerror or exc})") from None


def _restore_environ(saved):
    """Put this process's environment back to ``saved``. A ``LocalCluster``'s nannies set the variables meant for
    their workers (dask's ``distributed.nanny.pre-spawn-environ``: ``MALLOC_TRIM_THRESHOLD_``, ``OMP_NUM_THREADS``
    and others) in the process that starts them, where every process it starts later would inherit them (glibc's
    malloc then keeps its mmap threshold fixed, numpy's BLAS runs on one thread)."""
    for key in set(os.environ) - set(saved):
        del os.environ[key]
    for key, value in saved.items():
        if os.environ.get(key) != value:
            os.environ[key] = value


@contextlib.contextmanager
def connect(scheduler=None, cluster=None, timeout_s=10.0):
    """Within the block, joblib sends work to a Dask cluster; yields the number of worker threads (the runners'
    ``n_jobs``, at least 2 so that they do not run in this process).

    Parameters
    ----------
    scheduler : str, optional
        Address of a running ``dask scheduler`` (``tcp://host:8786``).
    cluster : int or None
        With ``scheduler`` None: a ``LocalCluster`` on this machine of this many single-threaded worker processes
        (None: one per core); this process's environment is as it was when the block ends.
    timeout_s : float
        How long to wait for the scheduler, s.

    Raises
    ------
    ValueError
        One line: distributed not installed, or no scheduler at ``scheduler``.
    """
    from joblib import parallel_config

    distributed = _distributed()
    with contextlib.ExitStack() as stack:
        if scheduler is not None:
            _probe(scheduler, timeout_s)
            try:
                client = stack.enter_context(distributed.Client(scheduler, timeout=f"{timeout_s}s"))
            except (OSError, TimeoutError, ValueError) as exc:
                raise ValueError(f"--scheduler {scheduler}: no Dask scheduler answered within {timeout_s:g} s "
                                 f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None
        else:
            stack.callback(_restore_environ, dict(os.environ))  # after the cluster has closed
            local = stack.enter_context(distributed.LocalCluster(n_workers=cluster, threads_per_worker=1,
                                                                 processes=True, dashboard_address=None))
            client = stack.enter_context(distributed.Client(local))
        threads = sum(client.nthreads().values())
        if threads < 1:
            raise ValueError(f"--scheduler {scheduler}: the cluster has no worker (start one: dask worker {scheduler})")
        with parallel_config(backend="dask"):
            yield max(2, threads)
