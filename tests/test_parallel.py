import os

import pytest
import torch

from tg_intrinsic.parallel import (WorkerDied, check_picklable, dumps,
                                   parallel_map, single_thread)


def threads_and_square(x):
    """The worker's torch thread count and a float computation."""
    return torch.get_num_threads(), float((torch.arange(50.0) * x).sum())


def fails_at_three(x):
    if x == 3:
        raise ValueError('three is bad')
    return x


def dies_at_two(x):
    if x == 2:
        os._exit(1)
    return x


def test_results_in_order_one_thread_and_the_same_for_any_workers():
    before = torch.get_num_threads()
    one = list(parallel_map(threads_and_square, range(7), 1, log=False))
    assert torch.get_num_threads() == before  # restored
    two = list(parallel_map(threads_and_square, range(7), 2, log=False))
    assert one == two
    assert [t for t, _ in two] == [1] * 7
    assert [s for _, s in one] == [1225.0 * x for x in range(7)]


@pytest.mark.parametrize('workers', [1, 2])
def test_errors_name_the_item(workers):
    with pytest.raises(ValueError, match='^number 3: three is bad$'):
        list(parallel_map(fails_at_three, range(6), workers, log=False,
                          name_of=lambda i, x: f'number {x}'))
    with pytest.raises(ValueError, match='^item 3: three is bad$'):
        list(parallel_map(fails_at_three, range(6), workers, log=False))
    # name None: the error as the function raised it
    with pytest.raises(ValueError, match='^three is bad$'):
        list(parallel_map(fails_at_three, range(6), workers, log=False,
                          name_of=lambda i, x: None))


def test_a_dead_worker_is_reported():
    done = []
    with pytest.raises(WorkerDied, match='a worker process died while '
                       r'computing item [0-2] or an item after it') as info:
        for result in parallel_map(dies_at_two, range(5), 2, log=False):
            done.append(result)
    assert info.value.index == len(done) <= 2


def test_unpicklable_functions_and_bad_counts():
    with pytest.raises(TypeError, match='the function .* cannot be sent to '
                       'worker processes.*workers=1'):
        list(parallel_map(lambda x: x, range(3), 2, log=False))
    assert list(parallel_map(lambda x: x + 1, range(3), 1,
                             log=False)) == [1, 2, 3]
    with pytest.raises(ValueError, match='workers'):
        list(parallel_map(abs, range(3), 0, log=False))
    with pytest.raises(TypeError, match='the pre_transform'):
        check_picklable(lambda d: d, 'pre_transform', 'MyData')
    check_picklable(abs, 'pre_transform', 'MyData')


def test_single_thread_returns_the_previous_counts():
    previous = single_thread((1, 1))
    try:
        assert torch.get_num_threads() == 1
    finally:
        assert single_thread(previous) == (1, 1)


def test_dumps_sends_a_view_without_its_whole_storage():
    import pickle
    from torch_geometric.data import Data
    big = torch.arange(100000.0)
    data = Data(pos=big[10:40].view(10, 3), y=big[:1])
    payload = dumps(data)
    assert len(payload) < 20000 < len(pickle.dumps(data))
    back = pickle.loads(payload)
    assert torch.equal(back.pos, data.pos) and torch.equal(back.y, data.y)
