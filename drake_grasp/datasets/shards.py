"""Resumable sharded jobs: worker processes on all cores, or a Ray cluster.

A job is split into numbered shards; shard k is a pure function of (job
arguments, k), so any worker can compute it and a rerun of the same command
computes only the shards whose files are missing. Each shard is written
atomically (`shard_00012.npz`), so Ctrl-C loses only the shards in flight.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import reprlib
import time
import zipfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

ShardFn = Callable[[int], dict[str, np.ndarray]]
MANIFEST = "manifest.json"
UNREADABLE = (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile)  # what np.load raises
ABANDON_WAIT_S = 10.0  # the longest an interrupt waits for the pool to fail the jobs of its ended workers [s]


def shard_path(out_dir: Path, k: int) -> Path:
    return out_dir / f"shard_{k:05d}.npz"


def shard_files(out_dir: Path) -> list[Path]:
    """The job's finished shards, in shard order."""
    return sorted(Path(out_dir).glob("shard_*.npz"))


def shard_index(path: Path) -> int:
    return int(path.stem.split("_")[1])


def shard_ranges(files: Sequence[Path]) -> str:
    """The shards' numbers as ranges: "0-8,10-55"."""
    ranges: list[list[int]] = []
    for n in sorted(shard_index(f) for f in files):
        if ranges and n == ranges[-1][1] + 1:
            ranges[-1][1] = n
        else:
            ranges.append([n, n])
    return ",".join(f"{a}-{b}" if b > a else f"{a}" for a, b in ranges)


def write_manifest(out_dir: Path, manifest: dict, *, size_key: str = "samples") -> None:
    """Records the job's arguments; a rerun with different arguments is refused.

    Only the job's size (`size_key`) may change: shards are pure functions of
    their index, so a larger rerun extends the same data set.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / MANIFEST
    if path.exists():
        try:
            old = json.loads(path.read_text())
        except json.JSONDecodeError:
            raise ValueError(f"corrupt {path}; remove it or use another --out") from None
        changed = sorted(k for k in set(old) | set(manifest)
                         if k != size_key and old.get(k) != manifest.get(k))
        if changed:
            raise ValueError(f"{out_dir} holds a different job (changed: {', '.join(changed)}); "
                             "use another --out or the same arguments")
    path.write_text(json.dumps(manifest, indent=1))


def drop_short_shards(out_dir: Path, expected_len: Callable[[int], int], key: str) -> None:
    """Removes shards holding fewer rows than a (now larger) job gives them, to recompute them."""
    for f in shard_files(out_dir):
        k = shard_index(f)
        try:
            with np.load(f) as data:
                short = len(data[key]) < expected_len(k)
        except UNREADABLE:
            short = True  # a damaged shard is recomputed like a short one
        if short:
            f.unlink()


def save_shard(out_dir: Path, k: int, arrays: dict[str, np.ndarray]) -> None:
    tmp = out_dir / f".shard_{k:05d}.{os.getpid()}.tmp.npz"
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, shard_path(out_dir, k))


def load_shards(out_dir: Path, files: Sequence[Path] | None = None) -> dict[str, np.ndarray]:
    """All finished shards of a job (or the `shard_files` given), concatenated in shard order."""
    files = shard_files(out_dir) if files is None else files
    if not files:
        raise ValueError(f"no data shards in {out_dir}")
    parts: dict[str, list[np.ndarray]] = {}
    for f in files:
        try:
            with np.load(f) as data:
                shard = {key: data[key] for key in data.files}
        except UNREADABLE as e:
            raise ValueError(f"corrupt data shard {f}: {e}; rerun the collection to recompute it") from None
        for key, array in shard.items():
            parts.setdefault(key, []).append(array)
    return {key: np.concatenate(v) for key, v in parts.items()}


POLL_S = 0.5  # how often `run_jobs` calls its `poll` while jobs run [s]


@dataclass(frozen=True)
class JobFailure:
    """A job that raised, yielded in place of its result by `run_jobs(..., keep_going=True)`."""

    error: Exception


def _failure(job: Any, error: Exception, keep_going: bool) -> JobFailure:
    """What a failed job becomes: bad input (ValueError) ends every job as it is; another error
    ends them as a RuntimeError naming the job, or is handed on when the others should go on."""
    if isinstance(error, ValueError):
        raise error
    if not keep_going:
        raise RuntimeError(f"job {reprlib.repr(job)} failed: {type(error).__name__}: {error}") from error
    return JobFailure(error)


def _run_local(fn: Callable[[Any], Any], pending: list, workers: int, worker_init: Callable[[], None] | None,
               poll: Callable[[], None] | None, keep_going: bool) -> Iterator[tuple[Any, Any]]:
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=ctx, initializer=worker_init) as pool:
        futures = {pool.submit(fn, job): job for job in pending}
        try:
            while futures:
                done, _ = wait(futures, timeout=POLL_S if poll else None, return_when=FIRST_COMPLETED)
                if poll is not None:
                    poll()
                for future in done:
                    job = futures.pop(future)
                    try:
                        result = future.result()
                    except Exception as e:
                        result = _failure(job, e, keep_going)
                    yield job, result
        except BaseException:  # an error, an interrupt, or the caller dropping the rest
            abandon_jobs(futures)
            raise


def abandon_jobs(futures: Iterable[Future]) -> None:
    """Ends this process's worker processes now, so that a job that stops early does not wait for the
    jobs in flight (whose results it would drop), and drops the jobs not yet started.

    The pool fails every unfinished job as broken once its workers are gone; the jobs are cancelled
    only after that, as Python 3.11's pool raises in its own thread on a cancelled job it fails."""
    futures = list(futures)
    for child in multiprocessing.active_children():
        child.terminate()
    wait(futures, timeout=ABANDON_WAIT_S)
    for future in futures:
        future.cancel()


def _apply(fn: Callable[[Any], Any], job: Any, worker_init: Callable[[], None] | None) -> Any:
    if worker_init is not None:
        worker_init()
    return fn(job)


def _run_ray(fn: Callable[[Any], Any], pending: list, address: str, worker_init: Callable[[], None] | None,
             poll: Callable[[], None] | None, keep_going: bool) -> Iterator[tuple[Any, Any]]:
    try:
        import ray
    except ImportError:
        raise ValueError("--ray-address needs Ray: pip install 'drake_grasp[ray]'") from None
    ray.init(address=address, ignore_reinit_error=True, log_to_driver=False)
    remote = ray.remote(_apply)
    refs = {remote.remote(fn, job, worker_init): job for job in pending}
    try:
        while refs:
            done, _ = ray.wait(list(refs), num_returns=1, timeout=POLL_S if poll else None)
            if poll is not None:
                poll()
            for ref in done:
                job = refs.pop(ref)
                try:
                    result = ray.get(ref)
                except Exception as e:
                    result = _failure(job, getattr(e, "cause", None) or e, keep_going)
                yield job, result
    except BaseException:
        for ref in refs:
            ray.cancel(ref)
        raise
    finally:
        ray.shutdown()


def run_jobs(fn: Callable[[Any], Any], jobs: list, *, workers: int = 0, ray_address: str | None = None,
             worker_init: Callable[[], None] | None = None, poll: Callable[[], None] | None = None,
             keep_going: bool = False) -> Iterator[tuple[Any, Any]]:
    """`fn(job)` for every job (a picklable value: a shard index, a run's description), in worker
    processes (one per core by default) or on a Ray cluster, yielded as (job, result) as they finish.

    `worker_init` runs once in each worker; `poll` runs in this process every `POLL_S` while jobs
    run. A job that raises ValueError (bad input) ends them all with it; another error ends them all
    as a RuntimeError naming the job, unless `keep_going`, which yields a `JobFailure` for it and goes
    on. Jobs in flight when the iteration stops early (an error, Ctrl-C, `close()`) are not waited for.
    """
    if ray_address:
        return _run_ray(fn, jobs, ray_address, worker_init, poll, keep_going)
    return _run_local(fn, jobs, workers or os.cpu_count() or 1, worker_init, poll, keep_going)


def run_shards(fn: ShardFn, *, num_shards: int, out_dir: Path, workers: int = 0,
               ray_address: str | None = None, unit: str = "labels",
               progress_stats: Callable[[dict], tuple[int, int]] | None = None,
               shard_size: int = 1, worker_init: Callable[[], None] | None = None,
               only: range | None = None, rows_of: Callable[[int], int] | None = None) -> int:
    """Computes the missing shards of a job (or of its shards `only`); returns how many it computed.

    `progress_stats(arrays) -> (count, positives)` feeds the progress bar's
    rate and positive rate; `rows_of(k)` is shard k's size where the last is shorter (else
    `shard_size`), so that the bar counts the job's own total; `worker_init` runs once in
    each worker process.
    `only` splits a job across machines: each computes its own range of shard
    indices into its own copy of the folder, and the shard files are merged after.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    wanted = range(num_shards) if only is None else range(max(only.start, 0), min(only.stop, num_shards))
    pending = [k for k in wanted if not shard_path(out_dir, k).exists()]
    done_before = len(wanted) - len(pending)
    size = rows_of or (lambda k: shard_size)
    bar = tqdm(total=sum(size(k) for k in wanted), initial=sum(size(k) for k in wanted if k not in pending),
               unit=unit, dynamic_ncols=True, smoothing=0.1)
    if done_before:
        bar.write(f"resuming: {done_before} of {len(wanted)} shards already in {out_dir}")
    results = run_jobs(fn, pending, workers=workers, ray_address=ray_address, worker_init=worker_init)
    count = positives = 0
    start = time.perf_counter()
    computed = 0
    try:
        for k, arrays in results:
            save_shard(out_dir, k, arrays)
            computed += 1
            n, pos = progress_stats(arrays) if progress_stats else (shard_size, 0)
            count, positives = count + n, positives + pos
            bar.update(n)
            bar.set_postfix_str(f"{count / (time.perf_counter() - start):.1f} {unit}/s, "
                                f"positive {positives / max(count, 1):.1%}")
    finally:
        bar.close()
    return computed
