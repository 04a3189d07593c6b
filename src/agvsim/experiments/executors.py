"""Where a sweep's runs execute: this process, a pool of local processes, or Ray.

Each executor takes the runs and yields ``(task, row)`` as runs finish, in any order; the
sweep writes each row as it comes. All run the same function (``runs.execute``), and a run's
numbers depend only on its scenario and seed, so every executor gives the same table.

Interrupting (Ctrl-C, or an exception raised by the consumer of the rows) cancels the runs
not yet started and stops the ones in flight; their rows are not kept, so they are redone
next time.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import socket
import threading
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from agvsim.experiments.runs import RunTask, execute


def default_workers() -> int:
    return max(1, os.cpu_count() or 1)


def run_serial(tasks: Sequence[RunTask]) -> Iterator[tuple[RunTask, dict]]:
    """One after the other in this process (``--workers 1``)."""
    for task in tasks:
        yield task, execute(task)


def _worker_init() -> None:
    # Ctrl-C goes to the whole process group: the parent decides, the workers carry on
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import numba

    numba.set_num_threads(1)  # one run per core: no nested parallel ray casting


def run_local(tasks: Sequence[RunTask], workers: int) -> Iterator[tuple[RunTask, dict]]:
    """A pool of ``workers`` fresh ('spawn') processes, one run at a time each."""
    if workers <= 1 or len(tasks) <= 1:
        yield from run_serial(tasks)
        return
    ctx = multiprocessing.get_context("spawn")  # numba's thread pools do not survive fork
    pool = ProcessPoolExecutor(
        max_workers=min(workers, len(tasks)), mp_context=ctx, initializer=_worker_init
    )
    futures: dict[Future, RunTask] = {pool.submit(execute, t): t for t in tasks}
    clean = False
    try:
        pending = set(futures)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in sorted(done, key=lambda f: futures[f].run_id):
                try:
                    row = fut.result()
                except BrokenProcessPool:
                    row = {"status": "error", "error": "the worker process died (out of memory?)"}
                yield futures[fut], row
        clean = True
    finally:
        if clean:
            pool.shutdown(wait=True)
        else:
            _stop(pool)


def _stop(pool: ProcessPoolExecutor) -> None:
    """Cancel what has not started and end the worker processes now."""
    kill = getattr(pool, "terminate_workers", None)  # Python >= 3.14
    if kill is not None:
        kill()
        return
    # before 3.14 there is no public way: shutdown() forgets the processes, so take them first
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        proc.terminate()
    for proc in procs:
        proc.join(5.0)


def ray_available() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def run_ray(
    tasks: Sequence[RunTask], address: str | None = None, num_cpus: int | None = None
) -> Iterator[tuple[RunTask, dict]]:
    """One Ray task per run, on a local Ray started here (``num_cpus``) or on the cluster at
    ``address`` (``auto``: the one ``ray start`` set up on this machine; ``ray://host:10001``:
    a remote one). A cluster's workers need agvsim installed and the scenario's files (maps,
    controllers) at the same absolute paths."""
    try:
        import ray
    except ImportError:
        raise RuntimeError(
            "Ray is not installed: pip install 'agvsim[ray]' (or pip install 'ray>=2.9,<3')"
        ) from None
    started = False
    handlers: dict[int, Any] = {}
    if not ray.is_initialized():
        address = address or os.environ.get("RAY_ADDRESS") or None
        kwargs: dict[str, Any] = {"logging_level": "ERROR", "log_to_driver": False}
        if address:
            kwargs["address"] = address
        else:
            kwargs.update(
                address="local",  # a new Ray for this sweep, even where `ray start` runs one
                num_cpus=num_cpus or default_workers(),
                include_dashboard=False,
                object_store_memory=100 * 1024**2,  # rows are small; do not reserve RAM
            )
        if address:
            _check_reachable(address)
        handlers = _signal_handlers()  # Ray's start replaces SIGTERM's (and may SIGINT's)
        try:
            ray.init(**kwargs)
        except Exception as err:  # noqa: BLE001 - Ray raises many kinds; say what failed
            _restore(handlers)
            where = f"connect to the Ray cluster at {address}" if address else "start Ray"
            raise RuntimeError(f"could not {where}: {type(err).__name__}: {err}") from None
        started = True
    remote = ray.remote(num_cpus=1, max_retries=0)(_ray_execute)
    refs: dict[Any, RunTask] = {}
    try:
        refs = {remote.remote(t): t for t in tasks}
        while refs:
            done, _ = ray.wait(list(refs), num_returns=1)
            for ref in done:
                task = refs.pop(ref)
                try:
                    row = ray.get(ref)
                except Exception as err:  # noqa: BLE001 - a lost worker or node
                    row = {"status": "error", "error": f"Ray task failed: {type(err).__name__}"}
                yield task, row
    finally:
        for ref in refs:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()
            _restore(handlers)  # the caller's Ctrl-C and SIGTERM handling, as it was


_HANDLED = (signal.SIGINT, signal.SIGTERM)


def _signal_handlers() -> dict[int, Any]:
    """The handlers of SIGINT and SIGTERM now (empty off the main thread, where Python can
    neither read nor set them)."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {int(s): signal.getsignal(s) for s in _HANDLED}


def _restore(handlers: dict[int, Any]) -> None:
    """Put back handlers taken by :func:`_signal_handlers` (one set outside Python, which
    ``getsignal`` reads as None, cannot be put back and is left as it is)."""
    for signum, handler in handlers.items():
        if handler is not None:
            signal.signal(signum, handler)


def _check_reachable(address: str) -> None:
    """Fail fast on a cluster address nothing answers at (Ray itself retries for minutes)."""
    hostport = address.removeprefix("ray://")
    host, sep, port = hostport.rpartition(":")
    if not sep or not port.isdigit() or not host:
        return  # "auto", "local" or a form Ray resolves itself
    try:
        socket.create_connection((host, int(port)), timeout=5.0).close()
    except OSError as err:
        raise RuntimeError(
            f"could not connect to the Ray cluster at {address}: nothing answers at "
            f"{host}:{port} ({err.strerror or err})"
        ) from None


def _ray_execute(task: RunTask) -> dict:
    import numba

    numba.set_num_threads(1)
    return execute(task)
