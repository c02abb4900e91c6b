"""Bounded work that stops: coding runs in worker processes that are ended at the deadline.

Intake.  A ``/v1/`` request's body is read in full first, within ``body_timeout`` seconds of
its arrival (else a 408 ``body-timeout`` problem), without holding a work slot: slow bodies
cannot starve the server.  Bodies over 1 MiB are spooled to disk.  The bytes of bodies read
and not yet answered are bounded in all by ``capacity × max_upload_bytes`` (past that: 503).

Admission.  With its body in, the request takes one of ``concurrency + queue_size`` slots, or
gets an immediate 503 with ``Retry-After``.  The slot is held until the response is sent and
the request's jobs have ended.

Fairness.  Clients (by address: :func:`client_key`) share the intake, the workers and the
slots.  With the intake budget full, a body from a client sending less than another takes the
room of that client's newest bodies still arriving (503 for them).  Jobs
waiting for a worker are dispatched round-robin between clients, not first come first served,
so one client's backlog does not delay another's job by more than one job per client ahead of
it.  When every slot is taken, a request from a client holding fewer slots than the client
holding most takes the slot of that client's newest job still waiting for a worker, which gets
the 503 instead: one client alone may use every slot, and many share them evenly.

Answers.  An answer of more than 1 MiB goes out in 1 MiB pieces while the request keeps its
slot; answers held so at once are bounded by ``answer_memory_bytes`` (past it, the newest
answers of a client holding more are cut, else a 503), and a client that stops reading is cut
after ``send_timeout``.

Work.  Jobs run in a pool of ``concurrency`` worker processes (:mod:`pebble`).  A job past the
request's deadline (``request_timeout`` from admission) is cancelled: its worker is killed
within about 0.1 s (SIGTERM, then SIGKILL), so its CPU and memory are freed, and the pool
starts a fresh worker.  A worker that dies (the kernel's OOM killer, a crash) answers its
request with a 503 ``worker-lost`` problem; a ``MemoryError`` (a worker's address space is
capped by ``worker_memory_bytes``) with a 413 ``out-of-memory`` problem.  Workers start warm:
they are forked from a fork server that has imported the service and coded a tiny input of
every kind (numba's on-disk cache loaded), and the pool reports ready once each has answered.

Why processes rather than cooperative checks in threads: the codec holds the GIL in its
entropy stage, so threads code on about one core; and a check between stages can stop a job
only between library calls, which for the largest allowed image last seconds
(docs/deploy.md, "Work that stops").  Why pebble: its futures, when cancelled or timed out,
end the one worker running them and the pool replaces it; ``concurrent.futures`` and loky can
only end the whole pool.

Jobs cross to the workers by pickle: ``fn`` must be a module-level function and its arguments
picklable (bytes, arrays, dicts).  An open file (an upload) is sent as its bytes.
"""

from __future__ import annotations

import asyncio
import atexit
import contextlib
import ctypes
import gc
import heapq
import io
import ipaddress
import logging
import multiprocessing
import os
import pickle
import resource
import tempfile
import threading
import time
from collections import Counter, deque
from collections.abc import Awaitable, Callable
from concurrent.futures import CancelledError, Future
from concurrent.futures import TimeoutError as FutureTimeout
from concurrent.futures.process import BrokenProcessPool
from typing import IO, Any, Protocol, TypeVar

import numpy as np
from pebble import ProcessExpired, ProcessPool
from starlette.requests import Request
from starlette.types import ASGIApp, Message, Receive, Scope, Send

import wavecore

from .errors import BodyTooLarge, Problem, send_problem
from .settings import Settings

T = TypeVar("T")
log = logging.getLogger("service")

# How long start-up waits for every worker to report warm before it goes on regardless.
WARM_TIMEOUT = 300.0
# A body is kept in memory up to this size while it arrives and waits, then on disk (/tmp),
# as Starlette does with uploads; it is replayed to the route in pieces of this size.
SPOOL_BYTES = 1 << 20


# --- in the worker processes --------------------------------------------------------------


_warm = False  # set by warm_up; a worker forked from a warm fork server inherits it


def warm_up() -> None:
    """Code a tiny input of each kind, so that every compiled kernel is loaded from the cache."""
    global _warm
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (64, 64, 3), dtype=np.uint8)
    grey = rgb[:, :, 0]
    for bundle in (
        wavecore.encode_image(rgb),
        wavecore.encode_image(grey[:32, :32], bpp=8.0),  # the rate search (slow on big inputs)
        wavecore.encode_image(grey, lossless=True),
        wavecore.encode_image(rgb.astype(np.uint16) * 257, lossless=True),
        wavecore.encode_image(grey / 255.0),
        wavecore.encode_curve(rgb[:, 0, :2] / 255.0),
        wavecore.encode_surface(rgb / 255.0),
    ):
        wavecore.decode(bundle)
        wavecore.decode(bundle, keep=0.5)
        wavecore.inspect(bundle)
    _warm = True


def worker_threads(concurrency: int) -> int:
    """The library's threads in each worker: the cores shared out among the workers.

    ``WAVECORE_THREADS`` set by the operator wins.  Otherwise each of ``concurrency`` workers
    gets ``cores // concurrency`` threads (at least 1), so busy workers do not fight over the
    cores: on 2 cores with 2 workers, one thread each gave 32 concurrent 512² encodes 1.9×
    the throughput of one client in sequence, against 1.6× with two threads each
    (``benchmarks/load.py``; docs/deploy.md).
    """
    with contextlib.suppress(ValueError):
        if int(os.environ.get("WAVECORE_THREADS", "0")) > 0:
            return int(os.environ["WAVECORE_THREADS"])
    return max(1, (os.cpu_count() or 1) // max(1, concurrency))


def _start_worker(memory_bytes: int, threads: int = 0) -> None:
    """A worker's initializer: cap its address space, set the library's thread count
    (:func:`worker_threads`), then warm up (unless forked warm)."""
    if memory_bytes > 0:
        resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
    if threads > 0:  # read by the library at each call, so it holds from the first job
        os.environ["WAVECORE_THREADS"] = str(threads)
    if not _warm:
        warm_up()


def _worker_pid(pause: float) -> int:
    time.sleep(pause)
    return os.getpid()


#: A worker gives its freed heap back only once it holds this much more than after its last
#: trim: below that, the next job reuses the pages instead of faulting them in again (a 512²
#: encode after a trim took 3-5 ms more, a fifth of its time), and an idle worker holds at
#: most this much more than it needs.
KEEP_FREE_BYTES = 64 << 20
_trimmed_rss: int | None = None  # this worker's resident bytes right after its last trim


def resident_bytes() -> int | None:
    """This process's resident memory (``/proc/self/statm``), or None where it cannot say."""
    try:
        with open("/proc/self/statm", "rb") as statm:
            return int(statm.read().split()[1]) * resource.getpagesize()
    except (OSError, ValueError, IndexError):
        return None


def _give_back_memory(collect: bool = True) -> None:
    """Return a job's freed memory to the system, so the worker idles small again.

    ``wavecore`` makes glibc keep freed arrays in its heap for the next coding
    (``wavecore._heap``); ``malloc_trim`` gives them back once the worker holds more than
    :data:`KEEP_FREE_BYTES` over what it held after its last trim (always where the resident
    size is unknown).  The resident size, not the heap's free count, decides: after a trim
    glibc still counts the pages it gave back as free.  ``collect`` first runs the garbage
    collector, for a failed job whose arrays may sit in reference cycles.
    """
    global _trimmed_rss
    if collect:
        gc.collect()
    resident = resident_bytes()
    if (
        resident is not None
        and _trimmed_rss is not None
        and resident <= _trimmed_rss + KEEP_FREE_BYTES
    ):
        return
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    _trimmed_rss = resident_bytes()


class JobProblem(Exception):
    """A :class:`~service.errors.Problem` raised in a worker, in a form that pickles."""

    def __init__(
        self, kind: str, detail: str, headers: dict[str, str], errors: list[Any] | None
    ) -> None:
        super().__init__(kind, detail, headers, errors)
        self.kind, self.detail, self.headers, self.errors = kind, detail, headers, errors


def _run_job(fn: Callable[..., T], args: tuple[Any, ...], kwargs: dict[str, Any]) -> T:
    """Run ``fn`` in a worker; exceptions come back as ones that survive the pickle.

    The exception is raised again outside the ``except`` block, stripped of its traceback
    and context: pebble keeps the last result until the next job, and a traceback would keep
    the failed job's frames, and so its arrays, alive in the idle worker.
    """
    try:
        result = fn(*args, **kwargs)
    except Exception as exc:
        error = _sendable_error(exc)
    else:
        _give_back_memory(collect=False)
        return result
    _give_back_memory(collect=isinstance(error, MemoryError))
    raise error


def _sendable_error(exc: Exception) -> Exception:
    if isinstance(exc, Problem):
        return JobProblem(exc.kind, exc.detail, exc.headers, exc.errors)
    if isinstance(exc, MemoryError):
        return MemoryError("the job ran out of memory")
    try:  # an exception whose __init__ takes other arguments cannot be re-created
        pickle.loads(pickle.dumps(exc))
    except Exception:
        return RuntimeError(f"{type(exc).__name__}: {exc}")
    exc.__traceback__ = exc.__context__ = exc.__cause__ = None
    return exc


# --- in the server process ----------------------------------------------------------------


class _SharedPools:
    """Process pools by (workers, memory cap), shared by the apps of one server process.

    A server has one app; tests build many apps in one process, and starting warm workers for
    each would cost seconds apiece.  A pool is stopped when the last app that started it
    stops (its lifespan), or at exit.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._pools: dict[tuple[int, int], tuple[ProcessPool, int]] = {}

    def get(self, workers: int, memory_bytes: int, *, hold: bool) -> ProcessPool:
        key = (workers, memory_bytes)
        with self._lock:
            pool, holders = self._pools.get(key, (None, 0))
            if pool is None or not pool.active:
                pool = ProcessPool(
                    max_workers=workers,
                    initializer=_start_worker,
                    initargs=(memory_bytes, worker_threads(workers)),
                    context=_context(),
                )
            self._pools[key] = (pool, holders + hold)
            return pool

    def release(self, workers: int, memory_bytes: int) -> None:
        key = (workers, memory_bytes)
        with self._lock:
            pool, holders = self._pools.get(key, (None, 0))
            if pool is None:
                return
            if holders > 1:
                self._pools[key] = (pool, holders - 1)
                return
            del self._pools[key]
        pool.stop()
        pool.join(timeout=10)

    def stop_all(self) -> None:
        with self._lock:
            pools = [pool for pool, _ in self._pools.values()]
            self._pools.clear()
        for pool in pools:
            pool.stop()
            pool.join(timeout=10)


def _context() -> Any:
    # forkserver: workers are forked from a clean single-threaded server process (forking
    # uvicorn itself, with its threads, is unsafe), which has imported the service and warmed
    # the kernels (service.forkserver_warm), so every worker, a replacement too, starts warm.
    ctx = multiprocessing.get_context("forkserver")
    # Under this package's own name: ``service`` in a checkout, ``wavecore_service`` when
    # installed. The jobs are pickled under that name, so the workers must have it imported.
    ctx.set_forkserver_preload([f"{__package__}.app", f"{__package__}.forkserver_warm"])
    return ctx


_POOLS = _SharedPools()
atexit.register(_POOLS.stop_all)


def client_key(scope: Scope) -> str:
    """Who sent a request, for sharing the work fairly: its client's address.

    An IPv6 client is its /64 network, which one host is usually given whole.  Behind a proxy
    the address is the proxy's unless uvicorn is told to trust its ``X-Forwarded-For``
    (``FORWARDED_ALLOW_IPS``; docs/deploy.md).
    """
    client = scope.get("client")
    host = str(client[0]) if client else ""
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return host
    if isinstance(address, ipaddress.IPv6Address):
        if address.ipv4_mapped is not None:
            return str(address.ipv4_mapped)
        return str(ipaddress.ip_network(f"{address}/64", strict=False))
    return str(address)


class _Preempted(Exception):
    """A waiting job gave its slot to a client holding fewer."""


class FairDispatcher:
    """Turns on the ``workers`` worker processes, shared out between clients.

    A job takes a turn (:meth:`acquire`) before it is sent to the pool and gives it back
    (:meth:`release`) when it has ended.  Waiting jobs are queued per client; a freed turn goes
    to the client with the fewest jobs running, and among those to the one served least
    recently.  Only called on the event loop.
    """

    def __init__(self, workers: int) -> None:
        self.free = workers
        self.running: Counter[str] = Counter()  # turns held, by client
        self._waiting: dict[str, deque[asyncio.Future[None]]] = {}
        self._served: dict[str, int] = {}  # when each client last got a turn (a count)
        self._turns = 0

    async def acquire(self, client: str) -> None:
        """Wait for a turn; :class:`_Preempted` if the job's slot was given to another."""
        if self.free > 0 and not self._waiting:
            self.free -= 1
            self._grant(client)
            return
        turn: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._waiting.setdefault(client, deque()).append(turn)
        try:
            await turn
        except asyncio.CancelledError:
            if turn.done() and not turn.cancelled() and turn.exception() is None:
                self.release(client)  # granted as the job was cancelled: pass the turn on
            else:
                self._forget(client, turn)
            raise

    def release(self, client: str) -> None:
        """Give back ``client``'s turn, to the next in line."""
        self.running[client] -= 1
        if self.running[client] <= 0:
            del self.running[client]
        self._tidy(client)
        while self._waiting:
            chosen = min(
                self._waiting,
                key=lambda waiting: (self.running[waiting], self._served.get(waiting, 0)),
            )
            queue = self._waiting[chosen]
            turn = queue.popleft()
            if not queue:
                del self._waiting[chosen]
            if not turn.done():
                self._grant(chosen)
                turn.set_result(None)
                return
        self.free += 1

    def preempt(self, client: str) -> bool:
        """Refuse ``client``'s newest waiting job (:class:`_Preempted`); False if it has none."""
        queue = self._waiting.get(client)
        while queue:
            turn = queue.pop()
            if not queue:
                del self._waiting[client]
                self._tidy(client)
            if not turn.done():
                turn.set_exception(_Preempted())
                return True
        return False

    def _grant(self, client: str) -> None:
        self._turns += 1
        self._served[client] = self._turns
        self.running[client] += 1

    def _forget(self, client: str, turn: asyncio.Future[None]) -> None:
        queue = self._waiting.get(client)
        if queue is not None and turn in queue:
            queue.remove(turn)
            if not queue:
                del self._waiting[client]
                self._tidy(client)

    def _tidy(self, client: str) -> None:
        # A client with nothing running or waiting is forgotten: back later, it goes first.
        if client not in self.running and client not in self._waiting:
            self._served.pop(client, None)


class Slot:
    """One admitted request; released when its response and its jobs are all done."""

    def __init__(self, pool: WorkPool, client: str = "") -> None:
        self._pool = pool
        self._holders = 1
        self.client = client
        self.started = time.monotonic()

    def hold(self) -> None:
        self._holders += 1

    def release(self) -> None:
        self._holders -= 1
        if self._holders == 0:
            self._pool.in_use -= 1
            self._pool.held[self.client] -= 1
            if self._pool.held[self.client] <= 0:
                del self._pool.held[self.client]


class WorkPool:
    """The worker processes, the admission count and the intake budget, sized from settings."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.capacity = settings.capacity
        self.in_use = 0
        self.held: Counter[str] = Counter()  # slots held, by client
        self.dispatch = FairDispatcher(settings.concurrency)
        self.answers = AnswerMemory(settings.answer_memory_bytes)
        self.rejected = 0
        self.intake_bytes = 0
        self.intake_budget = settings.capacity * settings.max_upload_bytes
        self.reading: list[BodyRead] = []  # bodies still arriving, oldest first
        self._held = False

    @property
    def processes(self) -> ProcessPool:
        # Got lazily, so that building an app starts no process (an app served without its
        # lifespan, as in tests, gets its pool at its first job).
        return _POOLS.get(self.settings.concurrency, self.settings.worker_memory_bytes, hold=False)

    def start(self) -> None:
        """Start the workers and wait until each is warm (blocking: call it off the loop)."""
        if not self._held:
            _POOLS.get(self.settings.concurrency, self.settings.worker_memory_bytes, hold=True)
            self._held = True
        pool = self.processes
        seen: set[int] = set()
        deadline = time.monotonic() + WARM_TIMEOUT
        # A worker runs its warm-up before its first job, so an answer from every worker
        # means every one is warm.  Rounds of short pauses let each worker take one.
        while len(seen) < self.settings.concurrency and time.monotonic() < deadline:
            jobs = [pool.submit(_worker_pid, None, 0.1) for _ in range(self.settings.concurrency)]
            seen.update(job.result() for job in jobs)

    def admit(self, client: str = "") -> Slot | None:
        """A slot for ``client``, or ``None`` when every slot is taken by clients holding no
        more than it would (only called on the event loop).

        When the slots are full, the client holding most that has a job waiting for a worker
        gives up its newest such job (a 503 for it), if it holds more slots than ``client``
        would with this one.  Until that job's request has answered, the slots are over-full
        by one.
        """
        if self.in_use >= self.capacity and not self._make_room(client):
            self.rejected += 1
            return None
        self.in_use += 1
        self.held[client] += 1
        return Slot(self, client)

    def make_intake_room(self, client: str, need: int) -> bool:
        """Make room in the intake budget for ``need`` more bytes of ``client``'s body, by
        refusing the newest bodies still arriving of clients that would still be sending more
        than ``client``.  False, refusing none, if that would not be enough (only called on
        the event loop)."""
        short = self.intake_bytes + need - self.intake_budget
        victims = _newest_of_biggest(self.reading, client, need, short)
        if victims is None:
            return False
        for victim in victims:
            victim.evicted.set_result(None)
            self.intake_bytes -= victim.size
            victim.size = 0
        return True

    def _make_room(self, client: str) -> bool:
        mine = self.held[client] + 1
        for holder, count in self.held.most_common():
            if count <= mine:
                return False
            if self.dispatch.preempt(holder):
                return True
        return False

    async def run(self, slot: Slot, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        """Run ``fn`` in a worker; a 503 ``timeout`` problem past the request's deadline."""
        loop = asyncio.get_running_loop()
        args = tuple(_sendable(arg) for arg in args)
        deadline = slot.started + self.settings.request_timeout
        try:
            async with asyncio.timeout(max(0.0, deadline - time.monotonic())):
                await self.dispatch.acquire(slot.client)  # this client's turn on a worker
        except TimeoutError:
            raise self._timeout() from None
        except _Preempted:
            self.rejected += 1
            raise self._preempted() from None
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            self.dispatch.release(slot.client)
            raise self._timeout()
        slot.hold()
        try:
            # pebble's own timeout is a backstop; the deadline is kept on this side.
            job: Future[T] = self.processes.submit(_run_job, remaining + 1, fn, args, kwargs)
        except RuntimeError:  # the pool was stopped (shutdown) or broke
            slot.release()
            self.dispatch.release(slot.client)
            raise self._worker_lost("the work pool is not running") from None

        def finished() -> None:
            slot.release()
            self.dispatch.release(slot.client)

        def done(_: Future[T]) -> None:
            with contextlib.suppress(RuntimeError):  # the loop may be closed at shutdown
                loop.call_soon_threadsafe(finished)

        job.add_done_callback(done)
        try:
            return await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(job)), remaining)
        except (TimeoutError, FutureTimeout):
            job.cancel()  # a running job's worker is killed and replaced
            raise self._timeout() from None
        except asyncio.CancelledError:
            job.cancel()  # the request itself was cancelled (client gone, shutdown)
            raise
        except JobProblem as exc:
            raise Problem(exc.kind, exc.detail, headers=exc.headers, errors=exc.errors) from None
        except MemoryError:
            limit = self.settings.worker_memory_bytes
            if limit:
                where = f"a worker's limit of {limit} bytes (WAVECORE_WORKER_MEMORY_BYTES)"
            else:
                where = "the worker could get"
            msg = f"the request needs more memory than {where}; send less data"
            raise Problem("out-of-memory", msg) from None
        except ProcessExpired as exc:
            log.warning("a worker ended during a job (exit code %s)", exc.exitcode)
            raise self._worker_lost(
                f"the worker coding this request stopped (exit code {exc.exitcode}), "
                "most likely out of memory; retry, or send less data"
            ) from None
        except BrokenProcessPool:
            # pebble gives up the whole pool when a worker dies with no job (an idle worker
            # killed from outside); the next job gets a new pool.
            log.warning("the work pool broke (a worker died while idle); starting a new one")
            raise self._worker_lost("the work pool restarted during the request") from None
        except CancelledError:
            raise self._worker_lost("the work pool stopped during the request") from None

    def _timeout(self) -> Problem:
        msg = (
            f"the request did not finish within {self.settings.request_timeout:g} s "
            "(WAVECORE_REQUEST_TIMEOUT); the server is busy or the input is very large"
        )
        return Problem("timeout", msg, headers={"Retry-After": str(self.settings.retry_after)})

    def _preempted(self) -> Problem:
        msg = (
            f"all {self.capacity} request slots are taken, and this client holds more of "
            "them than another client that asked for one: its newest request waiting for a "
            "worker gave its slot up; retry shortly"
        )
        return Problem("overloaded", msg, headers={"Retry-After": str(self.settings.retry_after)})

    def _worker_lost(self, detail: str) -> Problem:
        headers = {"Retry-After": str(self.settings.retry_after)}
        return Problem("worker-lost", detail, headers=headers)

    def shutdown(self) -> None:
        """Stop the workers (unless another app of this process still uses them)."""
        if self._held:
            self._held = False
            _POOLS.release(self.settings.concurrency, self.settings.worker_memory_bytes)


def _sendable(arg: Any) -> Any:
    """An open file (an upload, which may be spooled to disk) becomes its bytes, as a file."""
    if isinstance(arg, tempfile.SpooledTemporaryFile | io.BufferedIOBase | io.RawIOBase) and not (
        isinstance(arg, io.BytesIO)
    ):
        arg.seek(0)
        return io.BytesIO(arg.read())
    return arg


async def run_work(request: Request, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """Run CPU-bound ``fn(*args, **kwargs)`` for this request in a worker process.

    ``fn`` is a module-level function and its arguments pickle; its exceptions come back as
    they were raised (:class:`~service.errors.Problem` included).
    """
    pool: WorkPool = request.app.state.pool
    slot: Slot | None = request.scope.get("state", {}).get("work_slot")
    if slot is None:  # a route outside /v1/ (not admitted by the middleware)
        client = client_key(request.scope)
        slot = Slot(pool, client)
        pool.in_use += 1
        pool.held[client] += 1
        try:
            return await pool.run(slot, fn, *args, **kwargs)
        finally:
            slot.release()
    return await pool.run(slot, fn, *args, **kwargs)


class ClientNotReading(Exception):
    """A client stopped reading its answer (its connection is closed)."""


class HeldAnswer:
    """A large answer being sent: its client, its size, and a future set when it must give its
    room to another client's answer."""

    def __init__(self, client: str, size: int) -> None:
        self.client = client
        self.size = size
        self.cut: asyncio.Future[None] = asyncio.get_running_loop().create_future()


class AnswerMemory:
    """The bytes of large answers the server holds while their clients read them.

    Answers held at once are otherwise bounded only by the slots: ``(concurrency + queue) ×``
    the largest answer (66 × 67 MB for 66 clients that ask for a 67 MB array and read
    slowly).  Past ``limit`` (0: none) a new large answer takes the room of the newest answers
    of clients that would still hold more than its own client, which are cut; failing that it
    is refused, unless none is held: one answer alone always goes out.  Only used on the
    event loop.
    """

    def __init__(self, limit: int) -> None:
        self.limit = limit
        self.held = 0
        self.answers: list[HeldAnswer] = []  # oldest first

    def take(self, size: int, client: str = "") -> HeldAnswer | None:
        """Room for an answer of ``size`` bytes to ``client``, or None."""
        over = self.limit and self.held and self.held + size > self.limit
        if over and not self._make_room(size, client):
            return None
        answer = HeldAnswer(client, size)
        self.answers.append(answer)
        self.held += size
        return answer

    def give_back(self, answer: HeldAnswer) -> None:
        if answer in self.answers:  # (not if it was cut: given back then)
            self.answers.remove(answer)
            self.held -= answer.size

    def _make_room(self, size: int, client: str) -> bool:
        # Freeing every answer held is enough too: one answer alone always goes.
        short = min(self.held + size - self.limit, self.held)
        victims = _newest_of_biggest(self.answers, client, size, short)
        if victims is None:
            return False
        for victim in victims:
            self.give_back(victim)
            victim.cut.set_result(None)
        return True


class _Held(Protocol):
    client: str
    size: int


H = TypeVar("H", bound=_Held)


def _newest_of_biggest(held: list[H], client: str, need: int, short: int) -> list[H] | None:
    """What to take from other clients so that ``client`` gets ``short`` bytes of room for
    ``need`` more: the newest of ``held`` (oldest first) of whichever client holds most, as long
    as it would still hold more than ``client`` with ``need``; None if that is not enough."""
    holding: Counter[str] = Counter()
    by_client: dict[str, list[H]] = {}  # others' items, oldest first
    for item in held:
        holding[item.client] += item.size
        if item.size and item.client != client:
            by_client.setdefault(item.client, []).append(item)
    mine = holding[client] + need
    biggest = [(-holding[other], other) for other in by_client]
    heapq.heapify(biggest)
    victims: list[H] = []
    while short > 0:
        if not biggest or -biggest[0][0] <= mine:
            return None
        _, other = heapq.heappop(biggest)
        victim = by_client[other].pop()  # that client's newest
        victims.append(victim)
        holding[other] -= victim.size
        short -= victim.size
        if by_client[other]:
            heapq.heappush(biggest, (-holding[other], other))
    return victims


class _AnswersFull(Exception):
    def __init__(self, size: int, memory: AnswerMemory) -> None:
        super().__init__(size)
        self.size, self.held, self.limit = size, memory.held, memory.limit


class _Stopped(Exception):
    pass


async def _unless(work: Awaitable[T], stop: asyncio.Future[None]) -> T:
    """``await work``, or :class:`_Stopped` (``work`` cancelled) once ``stop`` is set."""
    task = asyncio.ensure_future(work)
    try:
        await asyncio.wait((task, stop), return_when=asyncio.FIRST_COMPLETED)
    finally:
        if not task.done():
            task.cancel()
    if stop.done():
        raise _Stopped
    return task.result()


async def _send_unless_cut(send: Send, message: Message, answer: HeldAnswer | None) -> None:
    """``send(message)``, or :class:`ClientNotReading` once ``answer`` is cut for another's."""
    if answer is None:
        await send(message)
        return
    try:
        await _unless(send(message), answer.cut)
    except _Stopped:
        msg = (
            f"the client's {answer.size}-byte answer was cut to make room for another "
            "client's: it held more answer memory (WAVECORE_ANSWER_MEMORY_BYTES) than that one"
        )
        raise ClientNotReading(msg) from None


def _paced(
    send: Send,
    stall: float,
    whole: float,
    memory: AnswerMemory | None = None,
    client: str = "",
) -> Send:
    """``send`` that hands a large body over in pieces of ``SPOOL_BYTES``.

    uvicorn buffers whatever one ``send`` gives it and waits for the client only before the
    next ``send``: a whole body in one message left the request's slot, and the next request's
    memory, free while the body sat in the connection's buffer (35 clients that never read a
    67 MB answer held 2.2 GB of the server).  In pieces, the request keeps its slot until its
    client has taken the body.  A client that takes no piece for ``stall`` seconds, or not the
    whole body within ``whole``, gets :class:`ClientNotReading`, and uvicorn closes the
    connection.

    The response's start is held back until its body comes, so that a large body that does not
    fit in ``memory`` can still be answered with a 503 instead (:class:`_AnswersFull`).  An
    answer cut to make room for another client's (:class:`AnswerMemory`) ends with
    :class:`ClientNotReading` too."""
    start: Message | None = None

    async def paced(message: Message) -> None:
        nonlocal start
        if message["type"] == "http.response.start":
            start = message
            return
        body = message.get("body", b"")
        if message["type"] != "http.response.body" or len(body) <= SPOOL_BYTES:
            if start is not None:
                await send(start)
                start = None
            await send(message)
            return
        answer = None
        if start is not None and memory is not None:
            answer = memory.take(len(body), client)
            if answer is None:
                raise _AnswersFull(len(body), memory)
        more = message.get("more_body", False)
        view = memoryview(body)
        try:
            if start is not None:
                await send(start)
                start = None
            async with asyncio.timeout(whole):
                for begin in range(0, len(view), SPOOL_BYTES):
                    piece = bytes(view[begin : begin + SPOOL_BYTES])
                    last = begin + SPOOL_BYTES >= len(view)
                    async with asyncio.timeout(stall):
                        await _send_unless_cut(
                            send,
                            {
                                "type": "http.response.body",
                                "body": piece,
                                "more_body": more or not last,
                            },
                            answer,
                        )
        except TimeoutError:
            msg = (
                f"the client did not read its {len(body)}-byte answer (no piece taken in "
                f"{stall:g} s, or not all in {whole:g} s)"
            )
            raise ClientNotReading(msg) from None
        finally:
            if memory is not None and answer is not None:
                memory.give_back(answer)

    return paced


class _ClientGone(Exception):
    pass


class BodyRead:
    """A request body still arriving: its client, its bytes so far, and a future set when it
    must give its room in the intake budget to another client's body."""

    def __init__(self, client: str) -> None:
        self.client = client
        self.size = 0
        self.evicted: asyncio.Future[None] = asyncio.get_running_loop().create_future()


class _Evicted(Exception):
    pass


class AdmissionMiddleware:
    """Read a ``/v1/`` request's body within the deadline, then admit it into a slot."""

    def __init__(self, app: ASGIApp, pool: WorkPool) -> None:
        self.app = app
        self.pool = pool

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not scope["path"].startswith("/v1/"):
            await self.app(scope, receive, send)
            return
        settings = self.pool.settings
        size = 0
        with tempfile.SpooledTemporaryFile(max_size=SPOOL_BYTES) as body:
            try:
                try:
                    async with asyncio.timeout(settings.body_timeout):
                        size = await self._read_body(receive, body, client_key(scope))
                except TimeoutError:
                    detail = (
                        "the request body did not arrive in full within "
                        f"{settings.body_timeout:g} s (WAVECORE_BODY_TIMEOUT)"
                    )
                    late = Problem("body-timeout", detail, headers={"Connection": "close"})
                    await send_problem(scope, send, late)
                    return
                except BodyTooLarge as exc:
                    detail = f"{exc.detail} (WAVECORE_MAX_UPLOAD_BYTES)"
                    closing = {"Connection": "close"}  # the rest of the body is not read
                    await send_problem(
                        scope, send, Problem("body-too-large", detail, headers=closing)
                    )
                    return
                except _ClientGone:
                    log.info("the client left before sending its whole body: %s", scope["path"])
                    scope.setdefault("state", {})["client_left"] = True  # metrics: 499, not 500
                    return
                except (_IntakeFull, _Evicted) as full:
                    detail = "too many request bodies are arriving at once; retry shortly"
                    if isinstance(full, _Evicted):
                        detail = (
                            "this client was sending more request bodies at once than another "
                            "that needed room; retry shortly"
                        )
                    # closed after the answer: the rest of the body is not read
                    headers = {"Retry-After": str(settings.retry_after), "Connection": "close"}
                    await send_problem(scope, send, Problem("overloaded", detail, headers=headers))
                    return
                slot = self.pool.admit(client_key(scope))
                if slot is None:
                    detail = (
                        f"all {self.pool.capacity} request slots are taken "
                        "(WAVECORE_CONCURRENCY + WAVECORE_QUEUE_SIZE); retry shortly"
                    )
                    headers = {"Retry-After": str(settings.retry_after)}
                    await send_problem(scope, send, Problem("overloaded", detail, headers=headers))
                    return
                scope.setdefault("state", {})["work_slot"] = slot
                body.seek(0)
                replayed = False

                async def replay() -> Message:
                    # The body again, in pieces of at most SPOOL_BYTES, as a client would send it.
                    nonlocal replayed
                    if not replayed:
                        chunk = body.read(SPOOL_BYTES)
                        replayed = body.tell() >= size
                        return {"type": "http.request", "body": chunk, "more_body": not replayed}
                    return await receive()  # after the body: only the disconnect is left

                paced = _paced(
                    send,
                    settings.send_timeout,
                    settings.request_timeout,
                    self.pool.answers,
                    client_key(scope),
                )
                try:
                    await self.app(scope, replay, paced)
                except _AnswersFull as full:
                    detail = (
                        f"the server holds {full.held} bytes of answers that clients are still "
                        f"reading, and this {full.size}-byte answer would pass its limit of "
                        f"{full.limit} (WAVECORE_ANSWER_MEMORY_BYTES); retry shortly"
                    )
                    headers = {"Retry-After": str(settings.retry_after)}
                    await send_problem(scope, send, Problem("overloaded", detail, headers=headers))
                except ClientNotReading as gone:
                    log.warning("%s: %s; its connection is closed", scope["path"], gone)
                finally:
                    slot.release()
            finally:
                self.pool.intake_bytes -= size

    async def _read_body(self, receive: Receive, body: IO[bytes], client: str) -> int:
        """Read the whole body into ``body``; its size, reserved of the intake budget.

        With the budget full, a body takes room from the newest bodies of clients sending
        more (:meth:`WorkPool.make_intake_room`); such a body ends with :class:`_Evicted`."""
        pool = self.pool
        reading = BodyRead(client)
        pool.reading.append(reading)
        try:
            while True:
                message = await _receive_unless(receive, reading.evicted)
                if message["type"] == "http.disconnect":
                    raise _ClientGone
                chunk = message.get("body", b"")
                if chunk:
                    if pool.intake_bytes + len(chunk) > pool.intake_budget and not (
                        pool.make_intake_room(client, len(chunk))
                    ):
                        raise _IntakeFull
                    pool.intake_bytes += len(chunk)
                    reading.size += len(chunk)
                    body.write(chunk)
                if not message.get("more_body", False):
                    return reading.size
        except BaseException:
            pool.intake_bytes -= reading.size  # (nothing, if evicted: given back then)
            raise
        finally:
            pool.reading.remove(reading)


async def _receive_unless(receive: Receive, evicted: asyncio.Future[None]) -> Message:
    """The next message, or :class:`_Evicted` once ``evicted`` is set."""
    try:
        return await _unless(receive(), evicted)
    except _Stopped:
        raise _Evicted from None


class _IntakeFull(Exception):
    pass
