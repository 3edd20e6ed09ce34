"""Dask engine for studies: one pure task per item, on a LocalCluster or on the cluster at an address.

Tasks are module-level functions of their arguments alone (no globals, nothing inherited from the client),
so a task gives the same numbers on any worker. What crosses the wire is plain Python data; compiled
CasADi code is built or loaded on each worker from its disk cache, never pickled. A worker that dies
mid-run loses nothing: the scheduler runs its tasks again on another worker. A task that raises is
recorded as failed with its message, never dropped.
"""
from __future__ import annotations

import contextlib
import dataclasses
import logging
import socket
from typing import Any, Callable, Iterator, Sequence

from tqdm import tqdm

from .._config import checked_settings, require
from .._progress import hidden
from ..errors import InputError

log = logging.getLogger(__name__)

_SRC = "EngineSettings"


@checked_settings(_SRC, workers="[1, 64]", connect_timeout_s="(0, 600]")
class EngineSettings:
    """``scheduler``: a Dask scheduler address (``tcp://host:port``); None starts a LocalCluster of
    ``workers`` single-threaded worker processes on this machine."""

    scheduler: str | None = None
    workers: int = 2
    connect_timeout_s: float = 10.0

    def __post_init__(self):
        require(self.scheduler is None or (isinstance(self.scheduler, str) and "://" in self.scheduler), _SRC,
                "scheduler", self.scheduler, "expected an address such as tcp://127.0.0.1:8786")
        require(isinstance(self.workers, int) and not isinstance(self.workers, bool), _SRC, "workers",
                self.workers, "expected an integer")


@dataclasses.dataclass(frozen=True)
class TaskOutcome:
    """One item's task: its ``value`` when ``success``, else the error's ``message``."""

    item: Any
    success: bool
    value: Any = None
    message: str = ""


@dataclasses.dataclass(frozen=True)
class EngineInfo:
    kind: str
    address: str
    workers: int

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@contextlib.contextmanager
def dask_client(settings: EngineSettings = EngineSettings()) -> Iterator[Any]:
    """A ``distributed.Client``: connected to ``settings.scheduler``, or to a LocalCluster it owns."""
    from distributed import Client, LocalCluster

    if settings.scheduler is None:
        with _dask_info_quiet(), LocalCluster(n_workers=settings.workers, threads_per_worker=1, processes=True,
                                              dashboard_address=":0", silence_logs=logging.ERROR) as cluster, \
                Client(cluster) as client:
            yield client
        return
    _probe(settings)
    try:
        client = Client(settings.scheduler, timeout=f"{settings.connect_timeout_s}s")
    except (OSError, TimeoutError, ValueError) as err:
        raise InputError("--scheduler", "address", settings.scheduler,
                         f"no Dask scheduler answered within {settings.connect_timeout_s:g} s ({err})") from None
    with client:
        yield client


@contextlib.contextmanager
def _dask_info_quiet() -> Iterator[None]:
    """Dask's INFO lines (its scheduler runs in this process: connections, workers added and removed, closing) off
    while a LocalCluster lives, its set-up and tear-down included (``silence_logs`` restores them before the
    tear-down); warnings and errors still show."""
    logger = logging.getLogger("distributed")
    level = logger.level
    logger.setLevel(max(level, logging.WARNING))
    try:
        yield
    finally:
        logger.setLevel(level)


def _probe(settings: EngineSettings) -> None:
    """A TCP address that refuses connections is refused at once (Dask would retry until its time-out)."""
    scheme, _, rest = settings.scheduler.partition("://")
    host, _, port = rest.rpartition(":")
    if scheme != "tcp":
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=settings.connect_timeout_s).close()
    except (OSError, ValueError) as err:
        raise InputError("--scheduler", "address", settings.scheduler,
                         f"no Dask scheduler there ({getattr(err, 'strerror', None) or err})") from None


def engine_info(client) -> EngineInfo:
    workers = client.scheduler_info().get("workers", {})
    return EngineInfo("dask", str(client.scheduler.address), len(workers))


def map_tasks(client, task: Callable[..., Any], items: Sequence[Any], *, progress: bool | None = True,
              desc: str = "tasks", **kwargs: Any) -> list[TaskOutcome]:
    """``task(item, **kwargs)`` for every item on the cluster, in item order; a bar on the client (``progress``:
    None on a terminal only). A task that raised is counted in the result, not logged inside the bar."""
    from distributed import as_completed

    futures = client.map(task, list(items), pure=False, **kwargs)
    index = {f.key: i for i, f in enumerate(futures)}
    outcomes: list[TaskOutcome | None] = [None] * len(futures)
    for future in tqdm(as_completed(futures), total=len(futures), desc=desc, disable=hidden(progress)):
        i = index[future.key]
        if future.status == "finished":
            outcomes[i] = TaskOutcome(items[i], True, future.result())
        else:
            err = future.exception()
            outcomes[i] = TaskOutcome(items[i], False, message=f"{type(err).__name__}: {err}")
            log.debug("task %s failed: %s", items[i], outcomes[i].message)
        future.release()
    return outcomes  # type: ignore[return-value]
