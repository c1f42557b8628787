r"""Pooling and unpooling between levels of a multiscale hierarchy."""
from .parallel_transport_pool import ParallelTransportPool
from .parallel_transport_unpool import ParallelTransportUnpool
from .gravo_pool import GravoPool
from .gravo_unpool import GravoUnpool
from .tangent_vector_pool import TangentVectorPool
from .global_max_pool import global_max_pool, dense_max_pool

__all__ = ['ParallelTransportPool', 'ParallelTransportUnpool', 'GravoPool',
           'GravoUnpool', 'global_max_pool',
           'dense_max_pool', 'TangentVectorPool']
