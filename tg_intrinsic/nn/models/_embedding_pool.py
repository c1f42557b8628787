r"""DeltaNet's global embedding and pooling as one CPU operation:

.. math::
    \mathbf{r}_b = \Big[\max_{i \in b} \mathbf{a}_i \,\Big\|\,
    \tfrac{1}{n} \textstyle\sum_{i \in b} \mathbf{a}_i\Big], \qquad
    \mathbf{a}_i = \sigma\big(\mathrm{BN}(W \mathbf{x}_i)\big),

with :math:`\sigma` the leaky ReLU and batch statistics over all points (or
the running ones in evaluation). The unfused layers write six tensors of
the size of :math:`W X` (16 x 2048 points x 1024 channels = 128 MiB each,
and every fresh one is paid again in page faults); here only
:math:`H = W X^\top` is stored, and the batch norm, activation, pooling and
their backward passes are numba sweeps over it, the last one writing
:math:`\partial H` over :math:`H` itself.
"""
import numpy as np
import torch
from numba import prange
from torch import Tensor
from torch.autograd.function import once_differentiable

from tg_intrinsic.geometry.jit import jit


class _EmbedAndPool(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x, weight, gamma, beta, norm, slope, size):
        h = torch.mm(weight, x.t())                        # [C, N]
        hn = h.numpy()
        if norm.training:
            mean, var = _channel_moments(hn)
            with torch.no_grad():   # as torch's BatchNorm1d updates them
                norm.num_batches_tracked.add_(1)
                momentum = norm.momentum if norm.momentum is not None \
                    else 1.0 / float(norm.num_batches_tracked)
                count = hn.shape[1]
                unbiased = var * count / max(count - 1, 1)
                norm.running_mean.mul_(1 - momentum).add_(
                    momentum * torch.from_numpy(mean).to(h.dtype))
                norm.running_var.mul_(1 - momentum).add_(
                    momentum * torch.from_numpy(unbiased).to(h.dtype))
        else:
            mean = norm.running_mean.double().numpy()
            var = norm.running_var.double().numpy()
        inv_std = 1.0 / np.sqrt(var + norm.eps)
        scale = gamma.detach().double().numpy() * inv_std
        shift = beta.detach().double().numpy() - scale * mean
        maximum, ties, average = _pool(hn, scale, shift, slope, size)
        ctx.save_for_backward(x, weight, h)
        ctx.state = (mean, inv_std, scale, shift, maximum, ties, slope,
                     size, norm.training)
        return torch.from_numpy(np.concatenate([maximum, average],
                                               1)).to(h.dtype)

    @staticmethod
    @once_differentiable
    def backward(ctx, grad):
        if ctx.state is None:
            raise RuntimeError(
                "the fused DeltaNet embedding overwrites its saved tensor "
                "in its backward pass, so it can be differentiated once per "
                "forward; run the forward again instead of "
                "backward(retain_graph=True) twice")
        x, weight, h = ctx.saved_tensors
        mean, inv_std, scale, shift, maximum, ties, slope, size, \
            training = ctx.state
        ctx.state = None
        hn = h.numpy()
        c = hn.shape[0]
        g = grad.double().numpy()
        g_max, g_mean = np.ascontiguousarray(g[:, :c]), \
            np.ascontiguousarray(g[:, c:])
        sum_dz, sum_dz_hat = _bn_sums(hn, mean, inv_std, scale, shift,
                                      maximum, ties, g_max, g_mean, slope,
                                      size)
        # BatchNorm's backward: the batch statistics depend on H as well.
        count = hn.shape[1]
        centre = sum_dz / count if training else np.zeros(c)
        tilt = sum_dz_hat / count if training else np.zeros(c)
        _write_grad_h(hn, mean, inv_std, scale, shift, maximum, ties,
                      g_max, g_mean, slope, size, centre, tilt)
        dh = h                                              # overwritten
        grad_x = torch.mm(dh.t(), weight) if ctx.needs_input_grad[0] \
            else None
        grad_w = torch.mm(dh, x) if ctx.needs_input_grad[1] else None
        dtype = weight.dtype
        return (grad_x, grad_w, torch.from_numpy(sum_dz_hat).to(dtype),
                torch.from_numpy(sum_dz).to(dtype), None, None, None)


def embed_and_pool(x: Tensor, linear: torch.nn.Linear,
                   norm: torch.nn.BatchNorm1d, slope: float,
                   size: int) -> Tensor:
    """``[max_i a_i || mean_i a_i]`` per example, ``a = leaky_relu(norm(
    linear(x)), slope)``, for ``size`` examples with equally many points
    laid out one after the other. CPU, float32 or float64, an affine
    batch norm that tracks running statistics and a bias-free linear map.

    Shapes:
        - **input:** x :math:`(B n, C_{in})`
        - **output:** :math:`(B, 2 C)`
    """
    return _EmbedAndPool.apply(x.contiguous(), linear.weight, norm.weight,
                               norm.bias, norm, float(slope), int(size))


def can_fuse(x: Tensor, linear: torch.nn.Linear,
             norm: torch.nn.BatchNorm1d) -> bool:
    # a synchronised batch norm (not a BatchNorm1d) takes its statistics
    # over all processes, which the fused sweep cannot
    # nor can it run in autocast's lower precision
    return (x.device.type == 'cpu' and x.dtype in (torch.float32,
                                                   torch.float64)
            and not torch.is_autocast_enabled(x.device.type)
            and isinstance(norm, torch.nn.BatchNorm1d)
            and linear.bias is None and norm.affine
            and norm.track_running_stats and x.size(0) > 1)


@jit(parallel=True)
def _channel_moments(h):  # pragma: no cover (numba)
    c, n = h.shape
    mean = np.empty(c)
    var = np.empty(c)
    for ch in prange(c):
        total = 0.0
        for i in range(n):
            total += h[ch, i]
        mu = total / n
        square = 0.0
        for i in range(n):
            d = h[ch, i] - mu
            square += d * d
        mean[ch] = mu
        var[ch] = square / n
    return mean, var


@jit(inline='always')
def _leaky_factor(z, slope):  # pragma: no cover (numba)
    """a = z * factor: branch-free (random signs mispredict), and one
    formula for the forward and backward sweeps, so tied maxima compare
    equal in both."""
    return slope + (1.0 - slope) * (z > 0.0)


@jit(inline='always')
def _grad_z(z, top, spread, share, slope):  # pragma: no cover (numba)
    """dL/dz of one entry: its share of the mean, plus its share of the
    maximum where it attains it."""
    factor = _leaky_factor(z, slope)
    return (spread + share * (z * factor == top)) * factor


@jit(parallel=True)
def _pool(h, scale, shift, slope, size):  # pragma: no cover (numba)
    c, n = h.shape
    per = n // size
    maximum = np.empty((size, c))
    average = np.empty((size, c))
    ties = np.zeros((size, c), dtype=np.int64)
    for task in prange(c * size):
        ch, b = task // size, task % size
        top = -np.inf
        count = 0
        total = 0.0
        for i in range(b * per, (b + 1) * per):
            z = scale[ch] * h[ch, i] + shift[ch]
            a = z * _leaky_factor(z, slope)
            total += a
            if a > top:
                top = a
                count = 1
            elif a == top:
                count += 1
        maximum[b, ch] = top
        ties[b, ch] = count
        average[b, ch] = total / per
    return maximum, ties, average


@jit(parallel=True)
def _bn_sums(h, mean, inv_std, scale, shift, maximum, ties, g_max, g_mean,
             slope, size):  # pragma: no cover (numba)
    c, n = h.shape
    per = n // size
    sum_dz = np.zeros(c)
    sum_dz_hat = np.zeros(c)
    for ch in prange(c):
        s0 = 0.0
        s1 = 0.0
        a_scale, a_shift, mu, inv = scale[ch], shift[ch], mean[ch], \
            inv_std[ch]
        for b in range(size):
            top, spread, share = maximum[b, ch], g_mean[b, ch] / per, \
                g_max[b, ch] / max(ties[b, ch], 1)
            for i in range(b * per, (b + 1) * per):
                dz = _grad_z(a_scale * h[ch, i] + a_shift, top, spread,
                             share, slope)
                s0 += dz
                s1 += dz * (h[ch, i] - mu)
        sum_dz[ch] = s0
        sum_dz_hat[ch] = s1 * inv
    return sum_dz, sum_dz_hat


@jit(parallel=True)
def _write_grad_h(h, mean, inv_std, scale, shift, maximum, ties, g_max,
                  g_mean, slope, size, centre, tilt):  # pragma: no cover
    """Overwrites H with dL/dH (BatchNorm's backward with the batch
    statistics' terms ``centre`` and ``tilt``; both 0 in evaluation)."""
    c, n = h.shape
    per = n // size
    for ch in prange(c):
        a_scale, a_shift, mu, inv = scale[ch], shift[ch], mean[ch], \
            inv_std[ch]
        offset = centre[ch] + tilt[ch] * (-mu * inv)
        slope_hat = tilt[ch] * inv
        for b in range(size):
            top, spread, share = maximum[b, ch], g_mean[b, ch] / per, \
                g_max[b, ch] / max(ties[b, ch], 1)
            for i in range(b * per, (b + 1) * per):
                hv = h[ch, i]
                dz = _grad_z(a_scale * hv + a_shift, top, spread, share,
                             slope)
                h[ch, i] = a_scale * (dz - offset - slope_hat * hv)
