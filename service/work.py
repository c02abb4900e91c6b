"""Bounded work: CPU-bound coding runs on a fixed thread pool, never on the event loop.

Every ``/v1/`` request takes a *slot* when it arrives, before its body is read; there are
``threads + queue_size`` slots.  A request that finds none free gets an immediate 503 with
``Retry-After`` instead of piling up.  A slot is held until the response is sent *and* every
job the request started has finished, so a job abandoned by a timeout keeps counting against
the bound until its thread is really free.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import time
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, TypeVar

from starlette.requests import Request
from starlette.types import ASGIApp, Receive, Scope, Send

from .errors import Problem, send_problem
from .settings import Settings

T = TypeVar("T")


class Slot:
    """One admitted request; released when its response and its jobs are all done."""

    def __init__(self, pool: WorkPool) -> None:
        self._pool = pool
        self._holders = 1
        self.started = time.monotonic()

    def hold(self) -> None:
        self._holders += 1

    def release(self) -> None:
        self._holders -= 1
        if self._holders == 0:
            self._pool.in_use -= 1


class WorkPool:
    """The thread pool and the admission count, both sized from the settings."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.capacity = settings.capacity
        self.in_use = 0
        self.rejected = 0
        self._executor: ThreadPoolExecutor | None = None

    @property
    def executor(self) -> ThreadPoolExecutor:
        # Created lazily so that building the app does no work (and no threads) at import.
        if self._executor is None:
            self._executor = ThreadPoolExecutor(
                self.settings.threads, thread_name_prefix="wavecore-work"
            )
        return self._executor

    def admit(self) -> Slot | None:
        """A slot, or ``None`` when every slot is taken (only called on the event loop)."""
        if self.in_use >= self.capacity:
            self.rejected += 1
            return None
        self.in_use += 1
        return Slot(self)

    async def run(self, slot: Slot, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        """Run ``fn`` on a worker thread; a 503 ``timeout`` problem past the request's deadline."""
        loop = asyncio.get_running_loop()
        slot.hold()
        job: Future[T] = self.executor.submit(functools.partial(fn, *args, **kwargs))

        def done(_: Future[T]) -> None:
            with contextlib.suppress(RuntimeError):  # the loop may be closed at shutdown
                loop.call_soon_threadsafe(slot.release)

        job.add_done_callback(done)
        remaining = slot.started + self.settings.request_timeout - time.monotonic()
        try:
            return await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(job)), remaining)
        except TimeoutError:
            job.cancel()  # only stops a job that has not started; a running one finishes
            msg = (
                f"the request did not finish within {self.settings.request_timeout:g} s "
                "(WAVECORE_REQUEST_TIMEOUT); the server is busy or the input is very large"
            )
            raise Problem(
                "timeout", msg, headers={"Retry-After": str(self.settings.retry_after)}
            ) from None

    def shutdown(self) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=False, cancel_futures=True)
            self._executor = None


async def run_work(request: Request, fn: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """Run CPU-bound ``fn`` for this request on the app's bounded pool."""
    pool: WorkPool = request.app.state.pool
    slot: Slot | None = request.scope.get("state", {}).get("work_slot")
    if slot is None:  # a route outside /v1/ (not admitted by the middleware)
        slot = Slot(pool)
        pool.in_use += 1
        try:
            return await pool.run(slot, fn, *args, **kwargs)
        finally:
            slot.release()
    return await pool.run(slot, fn, *args, **kwargs)


class AdmissionMiddleware:
    """Admit ``/v1/`` requests into a slot, or answer 503 at once when all are taken."""

    def __init__(self, app: ASGIApp, pool: WorkPool) -> None:
        self.app = app
        self.pool = pool

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not scope["path"].startswith("/v1/"):
            await self.app(scope, receive, send)
            return
        slot = self.pool.admit()
        if slot is None:
            detail = (
                f"all {self.pool.capacity} request slots are taken "
                "(WAVECORE_THREADS + WAVECORE_QUEUE_SIZE); retry shortly"
            )
            headers = {"Retry-After": str(self.pool.settings.retry_after)}
            await send_problem(scope, send, Problem("overloaded", detail, headers=headers))
            return
        scope.setdefault("state", {})["work_slot"] = slot
        try:
            await self.app(scope, receive, send)
        finally:
            slot.release()
