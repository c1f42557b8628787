r"""Pooling and unpooling between levels of a multiscale hierarchy."""
from .parallel_transport_pool import ParallelTransportPool
from .parallel_transport_unpool import ParallelTransportUnpool

__all__ = ['ParallelTransportPool', 'ParallelTransportUnpool']
