"""Where the tasks of ``trackproc batch`` run: this process, a process pool, or a Dask cluster.

The driver submits tasks with at most ``slots`` in flight (:func:`execute`); a pool whose
worker died is replaced and the tasks it took down re-run one by one, so that only the culprit
fails.

No process outlives the run: SIGTERM, SIGHUP or SIGINT to the driver raise :class:`Interrupted`
(:func:`interruptible`), and the run terminates its workers (:meth:`Executors.abort`) before it
exits; a driver killed outright (SIGKILL, the OOM killer) cannot do that, so each worker watches
for the driver's death itself (:func:`start_worker`), and the fork server and the resource
tracker of :mod:`multiprocessing` exit when the last worker has.

:mod:`multiprocessing`, :mod:`concurrent.futures` and the optional ``distributed`` are imported
by the executor that uses them, when a run starts one.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import os
import signal
import threading
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from typing import Callable, Sequence

from trackproc.errors import InputError, ProcessingError
from trackproc.pipeline.batch.config import Settings
from trackproc.pipeline.batch.kernels import compiled_kernels, load_numba
from trackproc.pipeline.batch.tasks import Task, TaskResult, run_task

log = logging.getLogger("trackproc.batch")

#: Thread-count variables of the BLAS/OpenMP libraries numpy and scipy may use.
BLAS_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS",
                         "NUMEXPR_NUM_THREADS")


def single_thread_blas() -> None:
    """One BLAS/OpenMP thread in this process (takes effect when set before numpy is imported).

    A batch runs its inputs in parallel, one per worker; threads inside the small matrix
    operations of one pass only contend for the same cores (ingest + smooth ran 4.4 times slower
    with OpenBLAS's default threads on a busy 2-core machine), and a threaded reduction may
    change the last bits of a sum. Worker processes always start with this; Dask's workers
    already do the same (``distributed.nanny.pre-spawn-environ``).
    """
    for name in BLAS_THREAD_VARIABLES:
        os.environ[name] = "1"


# ----------------------------------------------------------------------------- signals and orphans

#: The signals that stop a run cleanly (cron's and systemd's SIGTERM, a closed terminal, Ctrl-C).
STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP, signal.SIGINT)
#: How often a worker checks that its parent is alive (seconds).
PARENT_POLL_S = 0.5


class Interrupted(BaseException):
    """The run was stopped by a signal. A BaseException, as KeyboardInterrupt: no ``except
    Exception`` (a task's, a step's) may take it for a failure of the input it happened to
    interrupt. ``exit_code`` is the shell's 128 + signal number (143 for SIGTERM)."""

    def __init__(self, signum: int):
        self.signum = signum
        self.exit_code = 128 + signum
        super().__init__(f"stopped by {signal.Signals(signum).name}")


@contextlib.contextmanager
def interruptible():
    """Turn :data:`STOP_SIGNALS` into :class:`Interrupted` in this (main) thread for the block.

    Python's default SIGTERM kills the process on the spot, with no ``finally``: the worker pool
    would be left running. After the first signal the others are ignored, so the clean-up they
    asked for is not itself interrupted. Outside the main thread (where signals cannot be
    handled) the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum, frame):
        for number in STOP_SIGNALS:
            signal.signal(number, signal.SIG_IGN)
        raise Interrupted(signum)

    saved = {number: signal.signal(number, stop) for number in STOP_SIGNALS}
    try:
        yield
    finally:
        for number, handler in saved.items():
            signal.signal(number, handler)


def start_worker(driver: int, jit: bool = False) -> None:
    """Initializer of a pool worker: one BLAS thread, the stop signals left to the driver, and an
    exit of its own when the driver (pid ``driver``) dies.

    A worker killed with its driver would otherwise wait forever for tasks: with the forkserver
    start method its parent is the fork server, which itself lives until every worker has gone
    (each holds its "alive" pipe), so neither ``os.getppid()`` nor ``prctl(PR_SET_PDEATHSIG)``
    sees the driver die. A daemon thread checks every :data:`PARENT_POLL_S` seconds that the
    driver still runs (and that the worker has not been orphaned, for the spawn start method)
    and ends the worker when not. Workers write no files: killing one loses nothing.
    """
    single_thread_blas()
    if jit:                                       # compiled_kernels
        load_numba()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the whole group: the driver decides
    parent = os.getppid()
    if not _running(driver):  # died while this worker started
        os._exit(1)
    threading.Thread(target=_watch_driver, args=(driver, parent), name="trackproc-driver-watch",
                     daemon=True).start()


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie (killed, not yet reaped by its parent)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, another user's
        return True
    try:
        with open(f"/proc/{pid}/stat", "rb") as handle:  # Linux: "pid (name) STATE ..."
            return handle.read().rsplit(b")", 1)[1].split()[0] not in (b"Z", b"X")
    except (OSError, IndexError):
        return True  # no /proc: the signal check alone


def _watch_driver(driver: int, parent: int) -> None:
    while _running(driver) and os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


class SerialExecutor:
    """Runs each task in this process when it is submitted; ``jit``: the compiled kernels loaded
    first (:func:`compiled_kernels`)."""

    label = "this process (--workers 1)"
    slots = 1

    def __init__(self, jit: bool = False):
        if jit:
            load_numba()

    def submit(self, task: Task):
        future: Future = Future()
        future.set_result(run_task(task))
        return future

    @staticmethod
    def wait_first(futures):
        return set(futures), set()

    def close(self):
        pass

    abort = close


class PoolExecutor:
    """A process pool (forkserver start: no fork of this process's threads)."""

    def __init__(self, workers: int, jit: bool = False):
        method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
        context = multiprocessing.get_context(method)
        if method == "forkserver":
            # the server imports the steps' modules (and loads the kernels) once: each worker is
            # forked with them instead of importing them itself (read when the server starts)
            context.set_forkserver_preload(["trackproc.pipeline.batch.tasks", "trackproc.pipeline.batch.preload"
                                            + ("_jit" if jit else "")])
        self.workers = workers
        self.pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=start_worker,
                                        initargs=(os.getpid(), jit))
        self.jit = jit
        self.label = f"{workers} worker processes"
        self.slots = 2 * workers

    def submit(self, task: Task):
        return self.pool.submit(run_task, task)

    @staticmethod
    def wait_first(futures):
        done, pending = wait(futures, return_when=FIRST_COMPLETED)
        return done, pending

    def close(self):
        self.pool.shutdown(wait=True, cancel_futures=True)

    def abort(self):
        """Stop now: cancel what is queued and terminate the workers, mid-task (their results are
        lost, and not recorded: the next run does those inputs again)."""
        # the stdlib keeps no public handle on the workers before Python 3.14 (terminate_workers)
        processes = list((getattr(self.pool, "_processes", None) or {}).values())
        self.pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            with contextlib.suppress(Exception):
                process.terminate()
        for process in processes:
            with contextlib.suppress(Exception):
                process.join(timeout=5)
                if process.is_alive():
                    process.kill()
                    process.join(timeout=5)


class DaskExecutor:
    """An existing Dask distributed cluster (``tcp://host:port``)."""

    def __init__(self, address: str):
        try:
            from distributed import Client  # optional: the dask extra
        except ImportError:
            raise InputError("--scheduler needs Dask distributed, which is not installed", column="--scheduler",
                             found=address, expected="pip install 'trackproc[dask]' (or dask[distributed]), "
                                                     "or run without --scheduler") from None
        try:
            self.client = Client(address, timeout="20s", set_as_default=False)
        except Exception as exc:  # noqa: BLE001 - OSError, TimeoutError, ValueError (bad address) ...
            raise ProcessingError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
        threads = sum(self.client.nthreads().values()) or 1
        self.label = f"Dask scheduler {address} ({len(self.client.nthreads())} workers, {threads} threads)"
        self.slots = 2 * threads

    def submit(self, task: Task):
        import uuid  # here: only a Dask run names its tasks (uuid imports platform: ~5 ms a process)

        return self.client.submit(run_task, task, pure=False,
                                  key=f"trackproc-batch-{task.kind}-{task.key[:12]}-{uuid.uuid4().hex[:8]}")

    def wait_first(self, futures):
        from distributed import wait  # optional: the dask extra

        with self.client.as_current():
            result = wait(list(futures), return_when="FIRST_COMPLETED")
        return set(result.done), set(result.not_done)

    def close(self):
        with contextlib.suppress(Exception):
            self.client.close()

    abort = close  # the cluster's workers are the cluster's: closing the client releases our tasks


def _outcome(future, task: Task) -> TaskResult:
    """The task's result, or a failed result when the machinery failed (worker died, ...)."""
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001
        return TaskResult(kind=task.kind, name=task.name, key=task.key, status="failed",
                          error=f"internal error: {type(exc).__name__}: {exc}", error_type="internal",
                          trace=traceback.format_exc())


def _is_broken_pool(result: TaskResult) -> bool:
    return result.error_type == "internal" and "BrokenProcessPool" in (result.error or "")


def _run_isolated(task: Task) -> TaskResult:
    """Run one task in a fresh one-process pool (after a worker died: find the culprit)."""
    pool = PoolExecutor(1)
    try:
        result = _outcome(pool.submit(task), task)
    except BaseException:
        pool.abort()
        raise
    pool.close()
    return result


def execute(executor, tasks: Sequence, make_task: Callable, on_result: Callable) -> None:
    """Submit ``make_task(item)`` for each item with at most ``executor.slots`` in flight (so that
    input bytes are read only shortly before they are needed); ``on_result(item, result)``."""
    pending: dict = {}
    broken: list = []
    queue = list(tasks)
    queue.reverse()
    while queue or pending:
        while queue and len(pending) < executor.slots:
            item = queue.pop()
            task = make_task(item)
            if task is None:
                continue
            pending[executor.submit(task)] = (item, task)
        if not pending:
            break
        done, _ = executor.wait_first(set(pending))
        for future in done:
            item, task = pending.pop(future)
            result = _outcome(future, task)
            if isinstance(executor, PoolExecutor) and _is_broken_pool(result):
                broken.append((item, task))
                continue
            on_result(item, result)
        if broken and isinstance(executor, PoolExecutor):
            # a worker died: the pool is unusable; finish the rest in a new pool, and re-run the
            # tasks that were in flight one by one so that only the culprit fails
            log.warning("a worker process died; re-running the %d task(s) it took down, one at a time",
                        len(broken) + len(pending))
            for future, (item, task) in list(pending.items()):
                broken.append((item, task))
            pending.clear()
            executor.close()
            executor.__init__(executor.workers, executor.jit)
            for item, task in broken:
                on_result(item, _run_isolated(task))
            broken.clear()


class Executors:
    """Creates the executor when the first tasks need it (sized for them); closes it at the end."""

    def __init__(self, settings: Settings):
        self.settings = settings
        self.executor = None
        self.jit = compiled_kernels(settings)      # the tasks' Task.jit

    def get(self, n_tasks: int):
        if self.executor is None:
            self.executor = make_executor(self.settings, n_tasks, self.jit)
            log.info("running on %s", self.executor.label)
        return self.executor

    @property
    def label(self) -> str:
        return self.executor.label if self.executor is not None else "nothing to run"

    def close(self):
        if self.executor is not None:
            self.executor.close()

    def abort(self):
        """Stop the executor without waiting for its tasks (the run is being interrupted)."""
        if self.executor is not None:
            self.executor.abort()


def make_executor(settings: Settings, n_tasks: int, jit: bool = False):
    """The executor of a run: a Dask client, this process or a process pool; ``jit``: the tasks
    use the compiled kernels (:func:`compiled_kernels`), so the process that runs them loads them
    (this one with one worker, else the pool's fork server or each of its workers)."""
    scheduler = settings.get("batch.scheduler")
    if scheduler:
        if settings.origins.get("batch.workers") != "default":
            log.info("workers = %s is not used with a scheduler: the cluster's workers run the tasks",
                     settings.get("batch.workers"))
        return DaskExecutor(scheduler)
    workers = settings.get("batch.workers") or _cores()
    workers = max(1, min(workers, n_tasks))
    # with a pool this process runs no task and needs no kernel: the fork server loads them (or,
    # the first time on this installation, compiles them under jit.compile_once's locks) before it
    # forks the workers (preload_jit); without a fork server each worker's start_worker loads them
    # under the same locks, so one compiles and the others wait and load
    return SerialExecutor(jit) if workers == 1 else PoolExecutor(workers, jit)


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


