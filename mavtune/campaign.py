"""Campaigns of independent chunks (surface maps, the paper's reproduction, gain banks): run in this process by
default, or on an existing Dask cluster (`--scheduler tcp://HOST:8786`), with the same results for the same seeds.
A runner below everything it runs (it imports nothing of mavtune but its errors): the simulator's surfaces and the
application's campaigns both use it (tests/test_layers.py).

A chunk is one call `fn(*args)` of a module-level function whose result depends on its arguments alone (the
simulator draws its randomness from seeds among the arguments), so where a chunk runs, and how often — Dask
computes again the chunks of a worker it loses — does not change the result. Results come back in chunk order;
each is fetched as soon as it is done, so a worker lost later costs only its unfinished chunks.
"""

from __future__ import annotations

import uuid
from typing import Any, Callable, Sequence

from mavtune.errors import MavtuneError

CONNECT_TIMEOUT_S = 10.0


def run_chunks(fn: Callable[..., Any], chunks: Sequence[tuple], scheduler: str | None = None,
               done: Callable[[int, Any], None] | None = None, name: str = "chunk") -> list[Any]:
    """`[fn(*c) for c in chunks]`, in this process (scheduler None or "") or on the Dask cluster whose scheduler
    listens at `scheduler`; `done(i, result)` is called when chunk i is finished (on a cluster in the order they
    finish), so a caller can keep each result at once."""
    if not scheduler:
        results = []
        for i, args in enumerate(chunks):
            results.append(fn(*args))
            if done is not None:
                done(i, results[-1])
        return results
    return _on_dask(fn, chunks, scheduler, done, name)


def connect(scheduler: str):
    """A `distributed.Client` of the cluster at `scheduler`; an absent package or cluster is a one-line error."""
    try:
        from distributed import Client
    except ImportError:
        raise MavtuneError("--scheduler needs dask.distributed: pip install 'mavtune[dask]'") from None
    try:
        return Client(scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, ValueError, TypeError) as exc:
        raise MavtuneError(f"cannot reach the Dask scheduler {scheduler!r}: {exc}") from None


def _on_dask(fn: Callable[..., Any], chunks: Sequence[tuple], scheduler: str,
             done: Callable[[int, Any], None] | None, name: str) -> list[Any]:
    """Submit every chunk to the cluster, gather each result as it finishes, keep chunk order."""
    from distributed import KilledWorker, as_completed

    client = connect(scheduler)
    try:
        tag = f"mavtune-{name}-{uuid.uuid4().hex[:8]}"
        futures = [client.submit(fn, *args, key=f"{tag}-{i}") for i, args in enumerate(chunks)]
        index = {f.key: i for i, f in enumerate(futures)}
        results: list[Any] = [None] * len(futures)
        try:
            for future, result in as_completed(futures, loop=client.loop, with_results=True):
                i = index[future.key]
                results[i] = result
                future.release()  # the cluster may forget it: it is here now
                if done is not None:
                    done(i, result)
        except KilledWorker as exc:
            raise MavtuneError(f"Dask: {exc.allowed_failures + 1} workers died running {exc.task} "
                               "(see the worker logs)") from None
        return results
    finally:
        client.close()
