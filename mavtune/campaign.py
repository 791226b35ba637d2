"""Campaigns of independent chunks (surface maps, the paper's reproduction, gain banks): run in this process by
default, or on an existing Dask cluster (`--scheduler tcp://HOST:8786`), with the same results for the same seeds.

A chunk is one call `fn(*args)` of a module-level function whose result depends on its arguments alone (the
simulator draws its randomness from seeds among the arguments), so where a chunk runs, and how often — Dask
computes again the chunks of a worker it loses — does not change the result. Results come back in chunk order;
each is fetched as soon as it is done, so a worker lost later costs only its unfinished chunks.
"""

from __future__ import annotations

import io
import tempfile
import uuid
from pathlib import Path
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


def folder_files(folder: Path) -> dict[str, bytes]:
    """Every file under `folder` by its relative path (none if the folder does not exist): a run folder to ship."""
    folder = Path(folder)
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def write_files(folder: Path, files: dict[str, bytes]) -> None:
    """Write `files` (relative path -> bytes, from `folder_files`) under `folder`."""
    for rel, data in files.items():
        path = Path(folder) / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)


def run_in_folder(config: Any, files: dict[str, bytes]) -> tuple[dict[str, bytes], Any]:
    """`mavtune.run.run(config, folder)` in a scratch folder holding `files` (a chunk for a Dask worker, which
    need not share a disk with the client): the folder's files afterwards and the result. The journal travels
    with the folder, so a run resumes wherever it lands."""
    from rich.console import Console

    from mavtune.run import run

    with tempfile.TemporaryDirectory(prefix="mavtune-run-") as tmp:
        folder = Path(tmp) / "run"
        write_files(folder, files)
        result = run(config, folder, console=Console(file=io.StringIO(), emoji=False), quiet=True)
        return folder_files(folder), result
