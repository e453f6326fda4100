"""The Ray executor: the executor contract of :mod:`adpart.execution` on a Ray cluster.

``with RayExecutor(address) as ex: ex.map(fn, items)`` runs every item as a Ray task and returns
the results in the order of ``items``, like every executor. What Ray adds:

* **Scale-out.** ``address=None`` starts a private local Ray (shut down again on :meth:`close`);
  ``"host:port"`` or ``"ray://host:port"`` joins an existing cluster, whose nodes must have the
  same adpart installed (docs/scale-out.md).
* **Bounded retries.** A task whose worker process dies (killed, out of memory, node lost) is
  re-run up to ``max_retries`` times by Ray; an exception raised *by* ``fn`` is re-run only when
  ``retry_exceptions`` is true, since a deterministic error would fail the same way again.
* **Shared arrays through the object store.** A numpy array of at least :data:`SHARE_MIN_BYTES`
  that appears in the items (at any depth of dicts, lists and tuples) is ``ray.put`` once per
  ``map`` call - however many items refer to the same array object - and the workers read it
  zero-copy (read-only) from the object store instead of receiving a copy per task.

Ray is an optional dependency (``pip install 'adpart[ray]'``): this module imports it only
inside methods, so the plugin registers, and adpart works, without it.
"""

from __future__ import annotations

import logging
import socket
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, TypeVar

from adpart.errors import AdpartError
from adpart.execution import WORKER_THREAD_ENV, Executor
from adpart.params import build_settings, setting, settings, settings_params

T = TypeVar("T")
R = TypeVar("R")

#: Arrays at least this large are put in the object store once instead of travelling per task.
SHARE_MIN_BYTES = 64 * 1024
#: Seconds to wait for a TCP connection to a cluster address before calling it unreachable.
CONNECT_TIMEOUT_S = 5.0
INSTALL_HINT = "pip install 'adpart[ray]'"


class ClusterError(AdpartError, RuntimeError):
    """Ray is missing, a cluster cannot be reached, or a task was lost after its retries."""


def import_ray() -> Any:
    """The ``ray`` module, or a :class:`ClusterError` naming the install command."""
    try:
        import ray
    except ImportError as exc:
        raise ClusterError(
            f"the ray executor needs Ray, which is not installed ({exc}); install it with "
            f"{INSTALL_HINT}, or choose another executor (--executor local)"
        ) from None
    return ray


def _start_reaper() -> None:
    """Start :mod:`adpart.execution.reaper` for this process (where ``/proc`` exists), in its own
    session so that a signal to the driver's process group does not reach it."""
    import os
    import subprocess
    import sys

    if not os.path.isdir("/proc"):
        return
    subprocess.Popen(
        [sys.executable, "-m", "adpart.execution.reaper", str(os.getpid())],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True, close_fds=True,
    )


@dataclass(frozen=True)
class _Shared:
    """Placeholder for an array in the object store; replaced by the array inside the worker."""

    ref: Any


def _externalize(value: Any, put: Callable[[Any], Any], cache: dict[int, _Shared]) -> Any:
    """``value`` with every large array replaced by a :class:`_Shared` (one ``put`` per array)."""
    import numpy as np  # here, not at import: the executor plugins load for every command

    if isinstance(value, np.ndarray) and value.nbytes >= SHARE_MIN_BYTES:
        shared = cache.get(id(value))
        if shared is None:
            shared = cache[id(value)] = _Shared(put(value))
        return shared
    if isinstance(value, dict):
        return {k: _externalize(v, put, cache) for k, v in value.items()}
    if isinstance(value, list | tuple) and not hasattr(value, "_fields"):
        return type(value)(_externalize(v, put, cache) for v in value)
    return value


def _internalize(value: Any, get: Callable[[Any], Any]) -> Any:
    """Inverse of :func:`_externalize`, run in the worker."""
    if isinstance(value, _Shared):
        return get(value.ref)
    if isinstance(value, dict):
        return {k: _internalize(v, get) for k, v in value.items()}
    if isinstance(value, list | tuple) and not hasattr(value, "_fields"):
        return type(value)(_internalize(v, get) for v in value)
    return value


#: Ray workers get the local pool's thread settings (:data:`adpart.execution.WORKER_THREAD_ENV`)
#: through their runtime environment, set before the worker process imports numba.
_RUNTIME_ENV: dict[str, Any] = {"env_vars": dict(WORKER_THREAD_ENV)}


def _apply(fn: Callable[[Any], Any], item: Any) -> Any:
    """The Ray task body: resolve shared arrays, then ``fn(item)``."""
    import ray

    return fn(_internalize(item, ray.get))


def _split_address(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of ``host:port`` / ``ray://host:port``; None for ``auto``/``local``."""
    if address in {"auto", "local"}:
        return None
    bare = address.removeprefix("ray://")
    host, sep, port = bare.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ClusterError(
            f"Ray address {address!r} is not host:port or ray://host:port; give the address "
            "`ray start --head` printed (e.g. 10.0.0.5:6379), or omit --ray-address to start a "
            "local Ray"
        )
    return host.strip("[]"), int(port)


@settings
class RaySettings:
    """Where the Ray executor runs its tasks and how it retries them."""

    address: str | None = setting(None, kind="str", none="local")
    """Ray cluster address host:port or ray://host:port (local: start a local Ray here)."""
    num_cpus: int = setting(0, min=0, max=4096)
    """CPUs of a local Ray started here (0: all cores)."""
    max_retries: int = setting(3, min=0, max=1000)
    """Re-runs of a task whose worker died."""
    retry_exceptions: bool = setting(False)
    """Also re-run tasks that raised an exception."""


class RayExecutor(Executor):
    """Ray tasks on a local or remote Ray cluster; see the module docstring."""

    name = "ray"
    description = f"Ray tasks on a local or remote Ray cluster ({INSTALL_HINT})"
    params = settings_params(RaySettings)

    def __init__(self, **values: Any) -> None:
        self.settings = build_settings(RaySettings, values)
        self.address = self.settings.address or None
        self.num_cpus = self.settings.num_cpus
        self.max_retries = self.settings.max_retries
        self.retry_exceptions = self.settings.retry_exceptions
        self._started = False
        self._connected = False
        self._task: Any = None

    # ------------------------------------------------------------------ connection
    def connect(self) -> RayExecutor:
        """Join the cluster (or start a local one) now; later calls do nothing.

        ``map`` connects on first use; call this to fail early on a bad address.
        """
        if self._connected:
            return self
        ray = import_ray()
        if self.address is not None:
            self._check_reachable(self.address)
        if ray.is_initialized():
            # a Ray the caller (or a test fixture) initialised: use it, leave it running
            self._connected = True
            return self
        try:
            if self.address is None:
                ray.init(
                    address="local",
                    num_cpus=self.num_cpus or None,
                    include_dashboard=False,
                    logging_level=logging.WARNING,
                    runtime_env=_RUNTIME_ENV,
                )
                self._started = True
                _start_reaper()
            else:
                ray.init(address=self.address, logging_level=logging.WARNING,
                         runtime_env=_RUNTIME_ENV)
        except (ConnectionError, RuntimeError, TimeoutError, ValueError) as exc:
            where = (
                "a local Ray" if self.address is None else f"the Ray cluster at {self.address!r}"
            )
            raise ClusterError(
                f"cannot connect to {where}: {type(exc).__name__}: {exc}. Check that the cluster "
                "is running (`ray status`) with the same Ray and Python versions, or omit "
                "--ray-address to start a local Ray"
            ) from exc
        self._connected = True
        return self

    @staticmethod
    def _check_reachable(address: str) -> None:
        """Fail fast, naming the address, instead of waiting out Ray's own long timeouts."""
        target = _split_address(address)
        if target is None:
            return
        try:
            with socket.create_connection(target, timeout=CONNECT_TIMEOUT_S):
                pass
        except OSError as exc:
            raise ClusterError(
                f"cannot reach the Ray cluster at {address!r} ({exc.strerror or exc}); start one "
                f"there with `ray start --head --port={target[1]}`, correct --ray-address, or "
                "omit --ray-address to start a local Ray"
            ) from None

    def _remote(self) -> Any:
        ray = import_ray()
        if self._task is None:
            options: dict[str, Any] = {
                "max_retries": self.max_retries, "retry_exceptions": self.retry_exceptions
            }
            if not self._started and self.address is None:
                # a Ray the caller initialised: its job-level environment is not ours to set
                options["runtime_env"] = _RUNTIME_ENV
            self._task = ray.remote(_apply).options(**options)
        return self._task

    def _submit(self, fn: Callable[[Any], Any], items: Iterable[Any]) -> list[Any]:
        """Object refs of ``fn(item)`` for every item; shared arrays ``ray.put`` once."""
        self.connect()
        ray = import_ray()
        cache: dict[int, _Shared] = {}
        task = self._remote()
        refs = [task.remote(fn, _externalize(item, ray.put, cache)) for item in items]
        return refs

    def _lost(self, exc: Exception) -> ClusterError:
        return ClusterError(
            f"a Ray task was lost after {self.max_retries} retries ({type(exc).__name__}: "
            f"{str(exc).splitlines()[0] if str(exc) else ''}); raise --executor-opt "
            "max-retries=N, or check the cluster's nodes (`ray status`)"
        )

    def _get(self, ref: Any) -> Any:
        ray = import_ray()
        try:
            return ray.get(ref)
        except ray.exceptions.RayTaskError as exc:
            # the exception fn raised, re-raised as its own type
            raise exc.as_instanceof_cause() from None
        except ray.exceptions.RayError as exc:
            # worker crashed / node died / object lost, after Ray's retries
            raise self._lost(exc) from exc

    # ------------------------------------------------------------------ executor contract
    def map(self, fn: Callable[[T], R], items: Iterable[T]) -> list[R]:
        refs = self._submit(fn, items)
        try:
            return [self._get(ref) for ref in refs]
        except BaseException:
            self._cancel(refs)
            raise

    def imap_unordered(self, fn: Callable[[T], R], items: Iterable[T]) -> Iterator[tuple[int, R]]:
        """``(index, fn(items[index]))`` pairs as tasks finish, for streaming consumers.

        Unfinished tasks are cancelled if the consumer stops early or a task fails.
        """
        ray = import_ray()
        refs = self._submit(fn, items)
        index = {ref: i for i, ref in enumerate(refs)}
        waiting = list(refs)
        try:
            while waiting:
                ready, waiting = ray.wait(waiting, num_returns=1)
                for ref in ready:
                    yield index[ref], self._get(ref)
        finally:
            self._cancel(waiting)

    @staticmethod
    def _cancel(refs: list[Any]) -> None:
        """Cancel the tasks of ``refs`` that have not finished.

        Without force: a running task gets a KeyboardInterrupt where it next runs Python code,
        a queued one never starts. Force-killing a task whose reply is arriving aborts the
        driver in Ray 2.60 ("Check failed: ... Tried to complete task that was not pending",
        seen once in this project's CI when a task of ``map`` failed), so finished tasks are
        left alone and the worker processes are not killed."""
        if not refs:
            return
        ray = import_ray()
        _, pending = ray.wait(list(refs), num_returns=len(refs), timeout=0)
        for ref in pending:
            try:
                ray.cancel(ref)
            except (ValueError, TypeError, ray.exceptions.RayError):
                continue  # finished meanwhile, or already cancelled

    @property
    def parallelism(self) -> int:
        """CPUs of the cluster (connecting if needed): how many tasks run at once."""
        self.connect()
        return max(1, int(import_ray().cluster_resources().get("CPU", 1)))

    def close(self) -> None:
        """Shut down the local Ray if this executor started it (idempotent)."""
        if self._started:
            import_ray().shutdown()
        self._started = False
        self._connected = False
        self._task = None
