r"""Pooling and unpooling between levels of a multiscale hierarchy."""
from .parallel_transport_pool import ParallelTransportPool
from .parallel_transport_unpool import ParallelTransportUnpool
from .gravo_pool import GravoPool
from .gravo_unpool import GravoUnpool

__all__ = ['ParallelTransportPool', 'ParallelTransportUnpool', 'GravoPool',
           'GravoUnpool']
