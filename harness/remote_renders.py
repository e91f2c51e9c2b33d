"""Frames and references rendered as executor tasks and kept in this process's render store.

With an executor that runs tasks of several callers at once (``executor.concurrent``: the
``dask`` executor), a run asks for every frame and reference it needs without waiting: each
missing frame becomes a :class:`harness.units.FrameUnit` and each missing reference a series of
:class:`harness.units.ChunkUnit` (one per range of samples) on the workers. The client (this
process) owns the cache: it validates what comes back and stores it, and it adds the float64
sums of a reference's chunks in sample order (:meth:`RenderStore.reference` with
``map_chunks``), so the reference is the one a local render gives, bit for bit, and an
interrupted render resumes from its last stored chunk. Workers get the scene (it pickles, meshes
included) and return arrays: no shared file system is needed.
"""

from __future__ import annotations

import threading
from concurrent.futures import Future, ThreadPoolExecutor

from harness.buffers import Frame
from harness.executors.base import Executor, Shared
from harness.references import reference_record
from harness.renders import DEFAULT_CHUNK, REFERENCE_SEED, RenderStore
from harness.units import ChunkUnit, FrameUnit

#: client threads waiting on renders at once (each waits on tasks; none computes)
WAITING_THREADS = 64


class RenderFailed(RuntimeError):
    """A frame or chunk task ended in an error (the message names it)."""


class RemoteRenders:
    """Requests for frames and references of ``store``, rendered by ``executor``'s workers.

    Each request returns a ``concurrent.futures.Future`` at once; requests for the same cache
    entry while one is in flight share it. Renders that are not chunked (a renderer without
    ``accumulate``, an analytic reference) stay in this process, one at a time.

    Parameters
    ----------
    store : RenderStore
        The client's store and cache.
    executor : Executor
        Runs the frame and chunk tasks.
    chunk : int
        Samples per reference chunk (one task each, and one checkpoint).
    """

    def __init__(self, store: RenderStore, executor: Executor, *, chunk: int = DEFAULT_CHUNK):
        if isinstance(chunk, bool) or not isinstance(chunk, int) or chunk < 1:
            raise ValueError(f"chunk must be an integer >= 1, got {chunk!r}")
        self.store, self.executor, self.chunk = store, executor, chunk
        self._pool = ThreadPoolExecutor(WAITING_THREADS, thread_name_prefix="harness-render")
        self._in_flight: dict[str, Future] = {}
        self._lock = threading.RLock()  # a future done at once calls _forget in _once
        self._here = threading.Lock()

    def __enter__(self) -> RemoteRenders:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Stop waiting for renders not started yet."""
        self._pool.shutdown(wait=False, cancel_futures=True)

    # ----------------------------------------------------------------- requests
    def frame(self, scene, renderer: str, frame_index: int, *, spp: int, seed: int, channels) -> Future:
        """A future of the noisy frame (:meth:`RenderStore.frame`), rendered on a worker if missing."""
        scene = self.store.scene(scene) if isinstance(scene, str) else scene
        channels = frozenset(channels)
        key = self.store.key("frame", scene, renderer, frame_index, spp=spp, seed=seed, channels=sorted(channels))
        return self._once(key, lambda: self.store.frame(scene, renderer, frame_index, spp=spp, seed=seed,
                                                        channels=channels, render=self._frame_task(renderer)))

    def reference(self, scene, renderer: str, frame_index: int, *, spp: int, progress=None) -> Future:
        """A future of the reference (:meth:`RenderStore.reference`), its chunks rendered on workers."""
        scene = self.store.scene(scene) if isinstance(scene, str) else scene
        spec = self.store.registry.get("renderer", renderer)
        key = self.store.key("reference", scene, renderer, frame_index, spp=spp, seed=REFERENCE_SEED)
        if spp == 0 or not spec.chunked:
            def here():
                with self._here:
                    return self.store.reference(scene, renderer, frame_index, spp=spp, progress=progress)

            return self._once(key, here)
        return self._once(key, lambda: self.store.reference(
            scene, renderer, frame_index, spp=spp, chunk=self.chunk, progress=progress,
            map_chunks=self._chunk_tasks(scene, renderer, frame_index)))

    def reference_record(self, scene, renderer: str, frame_index: int, *, spp: int, target: float = 0.0,
                         progress=None) -> Future:
        """A future of the reference with its variance of the mean (:func:`harness.references.reference_record`).

        Its batches of samples are chunk tasks on the workers; the client adds them in sample
        order, so the image and the variance are the ones a local render gives, bit for bit.
        """
        scene = self.store.scene(scene) if isinstance(scene, str) else scene
        spec = self.store.registry.get("renderer", renderer)
        key = self.store.key("reference-moments", scene, renderer, frame_index, spp=spp, seed=REFERENCE_SEED,
                             target=float(target))
        if spp == 0 or not spec.chunked:
            def here():
                with self._here:
                    return reference_record(self.store, scene, renderer, frame_index, spp=spp, target=target,
                                            progress=progress)

            return self._once(key, here)
        return self._once(key, lambda: reference_record(
            self.store, scene, renderer, frame_index, spp=spp, target=target, chunk=self.chunk, progress=progress,
            map_chunks=self._chunk_tasks(scene, renderer, frame_index)))

    def _once(self, key: str, work) -> Future:
        with self._lock:
            future = self._in_flight.get(key)
            if future is None:
                future = self._in_flight[key] = self._pool.submit(work)
                future.add_done_callback(lambda _, key=key: self._forget(key))
            return future

    def _forget(self, key: str) -> None:
        with self._lock:
            self._in_flight.pop(key, None)

    # ----------------------------------------------------------------- tasks
    def _run_one(self, task):
        outcomes = [outcome for _, outcome in self.executor.run([task])]
        outcome = outcomes[0] if outcomes else None
        if outcome is None or not outcome.ok:
            raise RenderFailed(outcome.error if outcome is not None else f"{task.label}: no outcome")
        return outcome.value

    def _frame_task(self, renderer: str):
        settings = self.store.factory_settings(renderer)

        def render(scene, frame_index, *, spp, seed, channels, resolution) -> Frame:
            task = FrameUnit(scene.name, renderer, settings, frame_index, spp, seed, sorted(channels),
                             tuple(resolution), Shared(scene.content_hash(), scene))
            return Frame.from_arrays(self._run_one(task), owner=f"renderer {renderer!r} (on a worker)")

        return render

    def _chunk_tasks(self, scene, renderer: str, frame_index: int):
        settings = self.store.factory_settings(renderer)
        resolution = tuple(self.store.resolution(scene))

        def map_chunks(ranges):
            tasks = [ChunkUnit(scene.name, renderer, settings, frame_index, first, count, REFERENCE_SEED, resolution,
                               Shared(scene.content_hash(), scene)) for first, count in ranges]
            return self._in_order(tasks)

        return map_chunks

    def _in_order(self, tasks):
        """The chunk sums in the order of ``tasks``, whatever order they complete in."""
        ready, next_index = {}, 0
        for index, outcome in self.executor.run(tasks):
            if not outcome.ok:
                raise RenderFailed(outcome.error)
            ready[index] = outcome.value
            while next_index in ready:
                yield ready.pop(next_index)
                next_index += 1


__all__ = ["RemoteRenders", "RenderFailed"]
