"""One ordered parallel map over worker processes, shared by the data
sets' ``process()`` steps, training's preparation and ``tg-intrinsic
precompute``: Python's :class:`~concurrent.futures.ProcessPoolExecutor`
with the forkserver start method, one torch and numba thread per worker
(and in the main process with one worker), results in the order of the
items, a progress bar, and errors that name the failing item. The
results do not depend on the number of workers."""
import pickle
from collections import deque
from typing import Callable, Iterable, Iterator, Optional, Tuple

from tqdm.auto import tqdm

from tg_intrinsic.geometry.checks import check_positive_int

# The forkserver imports these once; every worker forks with them.
PRELOAD = ['torch', 'torch_geometric', 'tg_intrinsic.transforms',
           'tg_intrinsic.io']


class WorkerDied(RuntimeError):
    """A worker process ended without a result (killed, out of memory);
    :attr:`index` is the position of the first item left without a
    result (that one or a later one in flight was being computed)."""
    def __init__(self, message: str, index: int):
        super().__init__(message)
        self.index = index


def single_thread(threads: Tuple[int, int] = (1, 1)) -> Tuple[int, int]:
    """Sets the torch and numba thread counts to ``threads`` (one each by
    default, what every worker uses, so that results do not depend on the
    number of workers) and returns the previous counts."""
    import numba
    import torch
    previous = (torch.get_num_threads(), numba.get_num_threads())
    torch.set_num_threads(threads[0])
    numba.set_num_threads(threads[1])
    return previous


def pool_context():
    """The multiprocessing context of the pools: forkserver (with the
    heavy imports preloaded) where the platform has it, else spawn."""
    import multiprocessing
    if 'forkserver' in multiprocessing.get_all_start_methods():
        context = multiprocessing.get_context('forkserver')
        context.set_forkserver_preload(PRELOAD)
        return context
    return multiprocessing.get_context('spawn')


def check_picklable(obj, what: str, where: str):
    """Raises a :class:`TypeError` that says what to do when ``obj`` (the
    ``what`` of ``where``, e.g. the pre_transform of a data set) cannot be
    sent to worker processes."""
    try:
        pickle.dumps(obj)
    except Exception as error:  # noqa: BLE001 - any pickling failure
        raise TypeError(
            f"{where}: the {what} {obj!r} cannot be sent to worker "
            f"processes ({type(error).__name__}: {error}); pass workers=1, "
            f"or make it picklable: a function defined at module level or "
            f"an instance of a module-level class (lambdas and functions "
            f"defined inside other functions cannot be pickled)") from None


def _named(error: BaseException, name: str) -> BaseException:
    """``error`` of the same type with ``name`` in front of its message."""
    message = f"{name}: {error}"
    try:
        named = type(error)(message)
    except Exception:  # noqa: BLE001 - a type with another signature
        named = RuntimeError(message)
    if str(named) != message:
        named = RuntimeError(message)
    return named


def parallel_map(function: Callable, items: Iterable, workers: int = 1,
                 desc: str = 'processing', log: bool = True,
                 unit: str = 'item',
                 name_of: Optional[Callable] = None) -> Iterator:
    r"""Yields ``function(item)`` for every item, in the order of
    ``items``, computed by ``workers`` processes (one torch and numba
    thread each; with ``workers=1`` in this process, also single-threaded,
    so the results are the same for any number of workers).

    Items are read from ``items`` lazily and at most ``2 * workers`` are
    in flight, so memory stays bounded whatever the length. An exception
    raised for an item is raised again, of the same type, with the item's
    name (``name_of(index, item)``, default ``"item <index>"``; a name of
    ``None`` leaves the error as it is) in front of its message; a worker
    process that dies raises :class:`WorkerDied`.

    Args:
        function (callable): Applied to every item; with more than one
            worker it and the items must be picklable.
        items (iterable): The inputs.
        workers (int, optional): Worker processes. (default: :obj:`1`)
        desc (str, optional): Label of the progress bar and of errors.
            (default: :obj:`"processing"`)
        log (bool, optional): Show a progress bar. (default: :obj:`True`)
        unit (str, optional): Unit of the progress bar.
            (default: :obj:`"item"`)
        name_of (callable, optional): ``(index, item) -> str or None``,
            the item's name in error messages. (default: :obj:`None`)
    """
    workers = check_positive_int(workers, 'workers', 1)
    name_of = name_of or (lambda index, _: f'item {index}')
    total = len(items) if hasattr(items, '__len__') else None
    bar = tqdm(total=total, desc=desc, disable=not log, unit=unit)
    try:
        if workers == 1 or total == 1:
            yield from _serial(function, items, bar, name_of)
        else:
            check_picklable(function, 'function', desc)
            yield from _pooled(function, items, workers, bar, name_of,
                               desc)
    finally:
        bar.close()


def _serial(function, items, bar, name_of):
    threads = single_thread()
    try:
        for index, item in enumerate(items):
            try:
                result = function(item)
            except Exception as error:
                name = name_of(index, item)
                if not name:
                    raise
                raise _named(error, name) from error
            bar.update(1)
            yield result
    finally:
        single_thread(threads)


class _CompactPickler(pickle.Pickler):
    """Pickles a tensor that views part of a larger storage (an example
    sliced out of an InMemoryDataset) as a copy of that part, not with
    the whole storage."""
    def reducer_override(self, obj):
        import torch
        if isinstance(obj, torch.Tensor) and obj.layout == torch.strided \
                and not obj.is_sparse and obj.untyped_storage().nbytes() > \
                obj.numel() * obj.element_size():
            return obj.clone().__reduce_ex__(pickle.HIGHEST_PROTOCOL)
        return NotImplemented


def dumps(obj) -> bytes:
    """``obj`` pickled with plain pickle, tensors compacted (see
    :class:`_CompactPickler`): tensors travel inline in the bytes, rather
    than as the shared-memory handles of torch's multiprocessing pickler,
    which cost a round trip between the processes per tensor."""
    import io
    buffer = io.BytesIO()
    _CompactPickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(obj)
    return buffer.getvalue()


class _Pickled:
    """``function`` on a pickled item, its result pickled by
    :func:`dumps`."""
    def __init__(self, function):
        self.function = function

    def __call__(self, payload: bytes) -> bytes:
        return dumps(self.function(pickle.loads(payload)))


def _pooled(function, items, workers, bar, name_of, desc):
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=pool_context(),
                               initializer=single_thread)
    pending = deque()
    source = enumerate(items)
    work = _Pickled(function)

    def submit() -> bool:
        for index, item in source:
            payload = dumps(item)
            pending.append((index, name_of(index, item),
                            pool.submit(work, payload)))
            return True
        return False

    try:
        while len(pending) < 2 * workers and submit():
            pass
        while pending:
            index, name, future = pending.popleft()
            try:
                result = pickle.loads(future.result())
            except BrokenProcessPool:
                raise WorkerDied(
                    f"{desc}: a worker process died while computing "
                    f"{name or f'item {index}'} or an item after it (out "
                    f"of memory? try fewer workers)", index) from None
            except Exception as error:
                if not name:
                    raise
                raise _named(error, name) from error
            submit()
            bar.update(1)
            yield result
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)
