"""Where jobs run: a local pool of job processes, or Ray tasks (a local Ray instance or a cluster).

Both run the same thing, `execute(job, spec)`: one process per job (forked
from a server that has the job's module imported) with the job's timeout, so a result
never depends on the engine or on which worker ran it. A job that crashes, hangs or is killed is
a result with status `error`, never an exception here.
"""

from __future__ import annotations

import contextlib
import ctypes
import multiprocessing
import multiprocessing.context
import os
import resource
import signal
import socket
import sys
import tempfile
import threading
import time
import types
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from bagfault.errors import CampaignError

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator, Sequence
    from multiprocessing.connection import Connection
    from multiprocessing.process import BaseProcess

    from bagfault.campaign.placement import Placement

    Spec = dict[str, Any]
    Done = Callable[[int, dict[str, Any]], None]
    Job = Callable[[Spec], dict[str, Any]]  # a job spec to its result row, in the job's process (`bagfault.api.job`)

TERM_GRACE = 10.0  # seconds between SIGTERM (the job stops its system under test) and SIGKILL
PR_SET_PDEATHSIG = 1
_context: multiprocessing.context.ForkServerContext | None = None
_context_lock = threading.Lock()


def _forkserver(preload: str) -> multiprocessing.context.ForkServerContext:
    """Job processes are forked from a server that has imported the job's module (`preload`) and every built-in
    injector and assertion type's once: each job starts fresh, without paying the imports again (0.8 s of a
    1.4 s job on the test bags)."""
    from bagfault.assertions.registry import ASSERTION_TYPES  # noqa: PLC0415 - for their module names
    from bagfault.injectors.registry import BUILTIN  # noqa: PLC0415

    global _context  # noqa: PLW0603 - one server per worker process
    with _context_lock:
        if _context is None:
            types = {place.partition(':')[0] for place in [*BUILTIN.places.values(), *ASSERTION_TYPES.places.values()]}
            _context = multiprocessing.get_context('forkserver')
            _context.set_forkserver_preload([preload, 'bagfault.campaign.job', *sorted(types)])
        return _context


@contextlib.contextmanager
def _without_main() -> Iterator[None]:
    """While a job process starts: multiprocessing would import the caller's main script in it again (spawn
    semantics), running a script that calls `api.campaign` without a `__name__` guard once per job. The job
    needs nothing from it. Held under Running.lock, for the instant of `start()`."""
    main = sys.modules.get('__main__')
    sys.modules['__main__'] = types.ModuleType('__main__')
    try:
        yield
    finally:
        if main is not None:
            sys.modules['__main__'] = main


def cool_down() -> None:
    """Stop this process's fork server and resource tracker and reap them (the next campaign starts them again).
    multiprocessing has no public call for it; `_stop` is what its own tests use."""
    from multiprocessing import forkserver, resource_tracker  # noqa: PLC0415

    for helper in (getattr(forkserver, '_forkserver', None), getattr(resource_tracker, '_resource_tracker', None)):
        stop = getattr(helper, '_stop', None)
        if stop is not None:
            with contextlib.suppress(OSError, ChildProcessError):
                stop()


def warm_up(preload: str) -> int:
    """Start this process's fork server (the job's module imported) before the first job needs it; its pid."""
    from multiprocessing import forkserver  # noqa: PLC0415

    _forkserver(preload)
    forkserver.ensure_running()
    return os.getpid()


def _die_with_parent() -> None:
    """In the job process: killed when its parent dies (a worker or a Ray task cancelled by force)."""
    with contextlib.suppress(Exception):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


def _job_process(job: Job, spec: Spec, log: str, conn: Connection) -> None:
    """The job process: its own session, its output in `log`, its result sent back on `conn`. A stop that comes
    before its output goes to the log ends it quietly (the default actions): a traceback of an interrupted job
    never reaches the command's stderr."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    _die_with_parent()
    os.setsid()
    with contextlib.suppress(OSError):  # a Ray worker runs at nice 15; a job is the work, not housekeeping
        os.setpriority(os.PRIO_PROCESS, 0, 0)

    def interrupt(number: int, _frame: object) -> None:  # the engine's timeout: stop what the run started
        raise KeyboardInterrupt(signal.Signals(number).name)

    handle = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    os.dup2(handle, 1)
    os.dup2(handle, 2)
    signal.signal(signal.SIGTERM, interrupt)
    signal.signal(signal.SIGINT, interrupt)
    began = cpu_seconds()
    result = job(spec)
    conn.send({**result, 'cpu_s': round(cpu_seconds() - began, 3)})
    conn.close()


def cpu_seconds() -> float:
    """CPU seconds of this process (every thread) and of its children that ended (a system under test)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


class Running:
    """The job processes of this worker process, so an interrupt can end them."""

    processes: set[BaseProcess] = set()  # noqa: RUF012 - shared by the pool's threads on purpose
    lock = threading.Lock()

    @classmethod
    def end_all(cls) -> None:
        """SIGTERM every running job (each then stops what it started); SIGKILL after TERM_GRACE."""
        with cls.lock:
            processes = list(cls.processes)
        for process in processes:
            process.terminate()
        for process in processes:
            _reap(process)


def _reap(process: BaseProcess) -> None:
    """Wait TERM_GRACE for a job process to end (after SIGTERM, or its result), then SIGKILL it."""
    process.join(TERM_GRACE)
    if process.is_alive():
        process.kill()
        process.join()


def execute(job: Job, spec: Spec) -> dict[str, Any]:
    """Run one job in its own process; its result, or an `error` result saying what happened to it."""
    context = _forkserver(job.__module__)
    receiver, sender = context.Pipe(duplex=False)
    with tempfile.NamedTemporaryFile(prefix='bagfault-job-', suffix='.log') as log:
        process = context.Process(target=_job_process, args=(job, spec, log.name, sender), name='bagfault-job')
        with Running.lock, _without_main():
            process.start()
            Running.processes.add(process)
        sender.close()
        result: dict[str, Any] | None = None
        timed_out = False
        try:
            if receiver.poll(spec['timeout']):
                with contextlib.suppress(EOFError, OSError):
                    result = receiver.recv()
            else:
                timed_out = True
                process.terminate()
            _reap(process)
        finally:
            receiver.close()
            with Running.lock:
                Running.processes.discard(process)
        if timed_out:
            return _error(f'timed out after {spec["timeout"]:g} s (the campaign timeout)')
        if result is not None:
            return result
        lines = [line for line in Path(log.name).read_text(errors='replace').splitlines() if line.strip()]
    code = process.exitcode or 0
    how = f'killed by {signal.Signals(-code).name}' if code < 0 else f'exited with {code}'
    return _error(f'the job process {how} without a result' + (f': {lines[-1].strip()}' if lines else ''))


def _error(message: str) -> dict[str, Any]:
    return {'status': 'error', 'message': message, 'assertions': {}, 'detections': {}, 'seconds': None, 'cpu_s': None,
            'output': None}


class Engine(Protocol):
    """Runs job specs; `done(i, result)` is called in the caller's thread as each finishes."""

    def run(self, specs: Sequence[Spec], done: Done) -> None: ...

    def close(self) -> None: ...


class LocalEngine:
    """A pool of `workers` threads, each waiting on one job process at a time, running `job`."""

    def __init__(self, workers: int, job: Job) -> None:
        self.workers = workers
        self.job = job
        self.description = f'local pool of {workers} worker{"s" if workers != 1 else ""}'
        warm_up(job.__module__)

    def run(self, specs: Sequence[Spec], done: Done) -> None:
        """All specs; KeyboardInterrupt ends the running jobs and is raised again."""
        pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix='bagfault-job')
        futures: dict[Future[dict[str, Any]], int] = {}
        try:
            futures = {pool.submit(execute, self.job, spec): i for i, spec in enumerate(specs)}
            pending = set(futures)
            while pending:
                finished, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                for future in sorted(finished, key=futures.__getitem__):
                    done(futures[future], future.result())
        except BaseException:
            for future in futures:
                future.cancel()
            Running.end_all()
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)

    def close(self) -> None:
        """Nothing outlives the campaign: the fork server and multiprocessing's resource tracker are stopped
        and waited for (left to exit with the campaign's process, they stay zombies where PID 1 reaps none)."""
        cool_down()


TASK_RETRIES = 3  # times Ray runs a job again when its worker process or node was lost
NODES_EVERY = 1.0  # seconds between looks at the cluster's nodes while jobs end
RAY_CONNECT_TIMEOUT = 60.0  # seconds for ray.init to join a cluster (it takes 1-5 s; Ray itself waits for ever)


class RayEngine:
    """Every job a Ray task (one CPU each) on a local Ray instance or the cluster at `address`, running `job`."""

    def __init__(self, address: str | None, workers: int | None, job: Job) -> None:
        try:
            import ray  # noqa: PLC0415
        except ImportError:
            raise CampaignError('--ray needs Ray: pip install "bagfault[campaign]"') from None
        self.ray: Any = ray
        self.limit = workers
        self.job = job
        if address:
            _reachable(address)
        options: dict[str, Any] = {'include_dashboard': False, 'log_to_driver': False,
                                   'configure_logging': False}
        # a local instance's processes are this process's descendants; Ray kills its workers at shutdown, and
        # their fork servers, orphaned, would stay zombies where PID 1 reaps none: adopted and reaped here
        self._adopting = None if address else _Adoption()
        self._connect(address, workers, options)
        cpus = int(self.ray.cluster_resources().get('CPU', 1))
        if address == 'auto':  # the running cluster Ray found (RAY_ADDRESS, else the last `ray start` here)
            address = f'{self.ray.get_runtime_context().gcs_address} (auto)'
        self.description = f'Ray at {address} ({cpus} CPUs)' if address else f'a local Ray instance ({cpus} CPUs)'
        # a task whose worker or node dies (not one whose job failed: that is a result) runs again elsewhere
        self.task = ray.remote(num_cpus=1, max_retries=TASK_RETRIES)(execute)
        warm = ray.remote(num_cpus=1)(warm_up)
        ray.get([warm.remote(job.__module__) for _ in range(min(cpus, workers or cpus))])  # each one's fork server

    def _connect(self, address: str | None, workers: int | None, options: dict[str, Any]) -> None:
        """Join the cluster at `address`, or start a local instance of `workers` CPUs; CampaignError when neither
        works (a local instance's adoption of its processes undone)."""
        try:
            if address:
                _join_cluster(self.ray, address, options)
            else:
                # 'local': an instance of its own even when a cluster runs here (`ray start`, another suite's),
                # which Ray would otherwise join (RAY_ADDRESS, /tmp/ray/ray_current_cluster) and refuse num_cpus
                self.ray.init(address='local', num_cpus=workers or os.cpu_count() or 1, **options)
        except CampaignError:
            raise
        except Exception as exc:  # noqa: BLE001 - Ray raises many kinds; all mean "no cluster"
            if self._adopting is not None:
                self._adopting.reap(timeout=1.0)  # and this process is no subreaper any more
            where = f'the Ray cluster at {address}' if address else 'a local Ray instance'
            raise CampaignError(f'--ray: cannot start or reach {where}: {" ".join(str(exc).split())}') from None

    def run(self, specs: Sequence[Spec], done: Done) -> None:
        """All specs as tasks (at most `workers` at a time when given), each on the node `Placement` chooses for
        its bag; KeyboardInterrupt cancels them."""
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy  # noqa: PLC0415

        from bagfault.campaign.placement import Placement  # noqa: PLC0415

        ray = self.ray
        placement = Placement.of([spec['bag'] for spec in specs], self._nodes())
        running: dict[Any, tuple[int, str]] = {}
        stranded, looked = 0.0, time.monotonic()
        try:
            while placement.pending or running:
                for i, node in placement.assign(self.limit):
                    # soft: when the node is gone before the task starts, Ray runs it elsewhere
                    where = NodeAffinitySchedulingStrategy(node_id=node, soft=True)
                    running[self.task.options(scheduling_strategy=where).remote(self.job, specs[i])] = (i, node)
                if not running:  # no node with a CPU (one lost a moment ago): wait for one, not for ever
                    stranded = self._stranded(stranded, placement)
                    continue
                stranded = 0.0
                finished, _ = ray.wait(list(running), num_returns=1, timeout=0.2)
                self._collect(finished, running, placement, done)
                if finished and time.monotonic() - looked >= NODES_EVERY:  # a node lost or added since
                    looked = time.monotonic()
                    placement.nodes(self._nodes())
        except BaseException:
            for ref in running:
                with contextlib.suppress(Exception):
                    ray.cancel(ref, force=True)
            raise

    def _stranded(self, since: float, placement: Placement) -> float:
        """No node with a CPU since `since` (0: from now): a look at the nodes a moment later; CampaignError after
        RAY_CONNECT_TIMEOUT. When it began."""
        since = since or time.monotonic()
        if time.monotonic() - since > RAY_CONNECT_TIMEOUT:
            raise CampaignError(f'Ray: no node with a CPU for {RAY_CONNECT_TIMEOUT:g} s, {placement.pending} jobs '
                                'not run')
        time.sleep(0.2)
        placement.nodes(self._nodes())
        return since

    def _collect(self, finished: list[Any], running: dict[Any, tuple[int, str]], placement: Placement,
                 done: Done) -> None:
        """The finished tasks' results handed on, their nodes free again."""
        for ref in finished:
            i, node = running.pop(ref)
            placement.finished(node)
            done(i, self._result(ref))

    def _result(self, ref: Any) -> dict[str, Any]:
        """A finished task's result; a lost worker or node is the job's error."""
        try:
            result: dict[str, Any] = self.ray.get(ref)
        except Exception as exc:  # noqa: BLE001 - a lost worker or node is this job's error
            return _error(f'the Ray task failed: {" ".join(str(exc).split())[:500]}')
        return result

    def _nodes(self) -> dict[str, int]:
        """The cluster's live nodes and their whole CPUs (a node without one runs no job)."""
        return {node['NodeID']: int(node['Resources'].get('CPU', 0)) for node in self.ray.nodes()
                if node.get('Alive') and int(node['Resources'].get('CPU', 0)) > 0}

    def close(self) -> None:
        """Disconnect (and stop the local instance if this campaign started it, reaping what it leaves)."""
        self.ray.shutdown()
        if self._adopting is not None:
            self._adopting.reap()


PR_SET_CHILD_SUBREAPER = 36


class _Adoption:
    """This process as a subreaper while a local Ray instance runs: processes orphaned inside its tree come here
    instead of to PID 1, and `reap` collects them when Ray is stopped (only them: children this process had
    before are left to their owners)."""

    def __init__(self) -> None:
        self.before = _children()
        self.libc = ctypes.CDLL(None, use_errno=True)
        self.libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)

    def reap(self, timeout: float = 5.0) -> None:
        """Wait for the adopted processes to end and reap them; then stop adopting."""
        deadline = time.monotonic() + timeout
        try:
            while True:
                adopted = _children() - self.before
                for pid in adopted:
                    with contextlib.suppress(ChildProcessError):
                        os.waitpid(pid, os.WNOHANG)
                if not _children() - self.before or time.monotonic() > deadline:
                    return
                time.sleep(0.05)
        finally:
            self.libc.prctl(PR_SET_CHILD_SUBREAPER, 0, 0, 0, 0)


def _children() -> set[int]:
    """Pids whose parent is this process (from /proc)."""
    me, found = os.getpid(), set()
    for entry in os.listdir('/proc'):
        if entry.isdigit():
            with contextlib.suppress(OSError, IndexError, ValueError), \
                    open(f'/proc/{entry}/stat', encoding='ascii', errors='replace') as handle:
                if int(handle.read().rsplit(')', 1)[1].split()[1]) == me:
                    found.add(int(entry))
    return found


def _join_cluster(ray: Any, address: str, options: dict[str, Any]) -> None:
    """ray.init on a thread of its own, waited for RAY_CONNECT_TIMEOUT: a head that accepts connections and never
    answers, one reached under another address, or one that wants a token this driver lacks, kept ray.init
    retrying for minutes without a word. Meanwhile Ray's own retry warnings (its C++ core writes to descriptor 2)
    go nowhere; on time out the thread is left behind, a daemon, and descriptor 2 stays closed to it while
    sys.stderr, on a copy of the real one, carries the one line that says so."""
    failed: list[BaseException] = []

    def join() -> None:
        try:
            ray.init(address=address, **options)
        except BaseException as exc:  # noqa: BLE001 - handed to the waiting thread as it is
            failed.append(exc)

    sys.stderr.flush()
    real = os.dup(2)
    quiet = os.open(os.devnull, os.O_WRONLY)
    os.dup2(quiet, 2)
    os.close(quiet)
    thread = threading.Thread(target=join, name='ray-init', daemon=True)
    try:
        thread.start()
        thread.join(RAY_CONNECT_TIMEOUT)
    finally:
        if thread.is_alive():
            sys.stderr = open(real, 'w', encoding='utf-8', errors='replace', closefd=True)  # noqa: SIM115
        else:
            os.dup2(real, 2)
            os.close(real)
    if thread.is_alive():
        raise CampaignError(f'--ray {address}: Ray did not join the cluster within {RAY_CONNECT_TIMEOUT:g} s (a head '
                            'that does not answer, one started with token authentication while this shell has no '
                            'RAY_AUTH_TOKEN, or one whose nodes advertise another address than the one given)')
    if failed:
        raise failed[0]


def _reachable(address: str) -> None:
    """A HOST:PORT head answers a TCP connection within 5 s (Ray itself retries for minutes); CampaignError else."""
    host, _, port = address.rpartition(':')
    if not host or not port.isdigit() or '//' in address:
        return  # ray://, auto and the like: Ray's own resolution
    try:
        socket.create_connection((host, int(port)), timeout=5).close()
    except OSError as exc:
        raise CampaignError(f'--ray {address}: no Ray head answers there ({exc.strerror or exc})') from None


def make_engine(workers: int | None, ray: str | None, job: Job) -> Engine:
    """An engine running `job`: `ray` None the local pool (`workers` or one per core); '' a local Ray instance;
    else a cluster address."""
    if ray is None:
        return LocalEngine(workers or os.cpu_count() or 1, job)
    return RayEngine(ray or None, workers, job)
