import pytest
import torch
from torch_geometric.data import Batch, InMemoryDataset
from torch_geometric.loader import DataLoader

from tg_intrinsic import IntrinsicData


def make_example(n0, n1, n2, seed):
    g = torch.Generator().manual_seed(seed)
    e0, e1 = 3 * n0, 2 * n1
    sample_1 = torch.randperm(n0, generator=g)[:n1]
    sample_2 = torch.randperm(n1, generator=g)[:n2]
    nnz = 3 * n0
    return IntrinsicData(
        pos=torch.randn(n0, 3, generator=g),
        edge_index=torch.randint(n0, (2, e0), generator=g),
        grad_weight=torch.randn(e0, 2, generator=g),
        face=torch.randint(n0, (3, n0), generator=g),
        pos_1=torch.randn(n1, 3, generator=g),
        edge_index_1=torch.randint(n1, (2, e1), generator=g),
        sample_index_1=sample_1,
        cluster_1=torch.randint(n1, (n0, ), generator=g),
        prolong_index_1=torch.stack([torch.randint(n0, (nnz, ), generator=g),
                                     torch.randint(n1, (nnz, ), generator=g)]),
        prolong_weight_1=torch.rand(nnz, generator=g),
        num_nodes_2=n2,
        sample_index_2=sample_2,
        pool_edge_index_2=torch.stack([torch.randint(n1, (n1, ), generator=g),
                                       torch.randint(n2, (n1, ), generator=g)]),
        y=torch.tensor([seed]),
    )


def examples():
    return [make_example(20, 8, 3, 0), make_example(31, 11, 5, 1),
            make_example(12, 4, 2, 2)]


def assert_same(a, b):
    assert set(a.keys()) == set(b.keys())
    for key in a.keys():
        va, vb = a[key], b[key]
        # PyG returns Python scalars (num_nodes_l) as one-element tensors.
        assert torch.equal(torch.as_tensor(va).flatten(),
                           torch.as_tensor(vb).flatten()), key


def test_batch_round_trip():
    data_list = examples()
    batch = Batch.from_data_list(data_list)
    for i, data in enumerate(data_list):
        assert_same(batch.get_example(i), data)


def test_batch_offsets_point_into_the_right_level():
    data_list = examples()
    batch = Batch.from_data_list(data_list)
    n0 = [d.num_nodes for d in data_list]
    n1 = [d.pos_1.size(0) for d in data_list]
    # Example 1's level-1 indices are offset by example 0's level sizes.
    k = data_list[0].sample_index_1.numel()
    assert torch.equal(batch.sample_index_1[k:k + data_list[1].pos_1.size(0)],
                       data_list[1].sample_index_1 + n0[0])
    p0 = data_list[0].prolong_index_1.size(1)
    p1 = data_list[1].prolong_index_1.size(1)
    assert torch.equal(batch.prolong_index_1[:, p0:p0 + p1],
                       data_list[1].prolong_index_1
                       + torch.tensor([[n0[0]], [n1[0]]]))
    assert torch.equal(batch.cluster_1[n0[0]:n0[0] + n0[1]],
                       data_list[1].cluster_1 + n1[0])
    # Every index stays inside its level.
    assert batch.edge_index_1.max() < sum(n1)
    assert batch.pool_edge_index_2[1].max() < batch.level_size(2)
    assert batch.level_size(2) == sum(d.num_nodes_2 for d in data_list)


def test_level_batch_vectors():
    data_list = examples()
    batch = Batch.from_data_list(data_list)
    expected_1 = torch.cat([torch.full((d.pos_1.size(0), ), i)
                            for i, d in enumerate(data_list)])
    assert torch.equal(batch.level_batch(1), expected_1)
    expected_2 = torch.cat([torch.full((d.num_nodes_2, ), i)
                            for i, d in enumerate(data_list)])
    assert torch.equal(batch.level_batch(2), expected_2)
    assert torch.equal(batch.level_batch(0), batch.batch)
    single = data_list[0]
    assert torch.equal(single.level_batch(1), torch.zeros(8, dtype=torch.long))


def test_dataloader_round_trip():
    data_list = examples()
    loader = DataLoader(data_list, batch_size=2, shuffle=False)
    seen = []
    for batch in loader:
        seen.extend(batch.to_data_list())
    for a, b in zip(seen, data_list):
        assert_same(a, b)


def test_missing_level_size_is_a_clear_error():
    data = IntrinsicData(pos=torch.randn(5, 3),
                         edge_index_1=torch.zeros(2, 3, dtype=torch.long))
    with pytest.raises(ValueError, match="'pos_1' nor 'num_nodes_1'"):
        Batch.from_data_list([data, data])


def test_register_level_index():
    class MyData(IntrinsicData):
        pass

    MyData.register_level_index('up_index', (0, -1))
    a = MyData(pos=torch.randn(4, 3), pos_1=torch.randn(2, 3),
               up_index_1=torch.tensor([[0, 1], [3, 2]]))
    batch = Batch.from_data_list([a, a])
    assert batch.up_index_1.tolist() == [[0, 1, 2, 3], [3, 2, 7, 6]]
    assert 'up_index' not in IntrinsicData.level_index_keys
    with pytest.raises(ValueError):
        MyData.register_level_index('bad', (1, ))


class ListDataset(InMemoryDataset):
    def __init__(self, root, data_list=None):
        self._list = data_list
        super().__init__(root)
        self.load(self.processed_paths[0], data_cls=IntrinsicData)

    @property
    def processed_file_names(self):
        return ['data.pt']

    def process(self):
        self.save(self._list, self.processed_paths[0])


def test_in_memory_dataset_save_load(tmp_path):
    data_list = examples()
    ListDataset(str(tmp_path), data_list)
    dataset = ListDataset(str(tmp_path))  # loads from disk
    assert len(dataset) == 3
    for i, data in enumerate(data_list):
        loaded = dataset[i]
        assert isinstance(loaded, IntrinsicData)
        assert_same(loaded, data)
    batch = Batch.from_data_list([dataset[0], dataset[2]])
    assert_same(batch.get_example(1), data_list[2])
