"""When a layer must send per-edge messages through PyG's ``propagate``
instead of its sparse fast path: PyG's explainers set an edge mask
(``explain=True``), and hooks see only what runs through ``propagate``."""
from torch_geometric.nn import MessagePassing


def sets_per_edge_machinery(conv: MessagePassing) -> bool:
    """Whether an edge mask or a propagate, message or aggregate hook is
    set on ``conv``."""
    return bool(conv.explain) or any(len(hooks) > 0 for hooks in (
        conv._propagate_forward_pre_hooks, conv._propagate_forward_hooks,
        conv._message_forward_pre_hooks, conv._message_forward_hooks,
        conv._aggregate_forward_pre_hooks, conv._aggregate_forward_hooks))
