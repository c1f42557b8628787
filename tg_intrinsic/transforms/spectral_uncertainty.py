import math

from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry.checks import (check_positive_float,
                                           check_positive_int)
from tg_intrinsic.geometry.appearance.brdf import (observed_spectra,
                                                   spectral_uncertainty)
from tg_intrinsic.geometry.appearance.sh import torrance_sparrow_to_principled
from tg_intrinsic.transforms._batching import GraphTransform


@functional_transform('spectral_uncertainty')
class SpectralUncertainty(GraphTransform):
    r"""Per-point uncertainty of the specular parameters from power spectra
    (functional name: :obj:`spectral_uncertainty`). It follows eqs.
    5.19-5.25 of Wiersma et al., "Uncertainty for SVBRDF Acquisition using
    Frequency Analysis" (SIGGRAPH 2025).

    A grid over :math:`(K_s, r)` (roughness :math:`r`, :math:`\alpha = r^2`)
    scores

    .. math::
        D(K_s, \alpha) = \sum_{l \geq 1} \left(S_B(l) - K_s^2
        e^{-2(\alpha^2 - \alpha'^2) l^2} S_L(l)\right)^2

    on the spectra of ``sh_out`` and ``sh_in_obs`` (both divided by the
    light's power), turns it into a distribution :math:`d \propto
    e^{-D/(2\sigma^2)}` and reports its normalised entropy :math:`H =
    -\sum d \log d / \log n` in :math:`[0, 1]` (see
    :func:`~tg_intrinsic.geometry.appearance.brdf.spectral_uncertainty`). The argmax
    initialises the recovery: :math:`K_s` per channel and :math:`\alpha`,
    then :math:`K_d` from degree 0, where the observed mean is :math:`K_d
    E / \pi` plus the specular mean,

    .. math::
        K_d = \frac{\pi\,(B_{00} - K_s L_{00})}{\sqrt{4\pi}\, E},

    mapped to principled parameters with
    :func:`~tg_intrinsic.geometry.appearance.sh.torrance_sparrow_to_principled`.

    Args:
        grid (tuple, optional): Cells ``(specular, roughness)``.
            (default: :obj:`(32, 32)`)
        sigma (float, optional): :math:`\sigma` of the likelihood.
            (default: :obj:`1e-2`)
        store_likelihood (bool, optional): Keep the grid distribution
            (``N * cells`` numbers). (default: :obj:`True`)

    Shapes:
        - **input:** ``sh_in_obs``, ``sh_out`` :math:`(N, K, 3)`,
          ``irradiance`` :math:`(N, 3)`, ``sh_prefilter`` (from
          :class:`~tg_intrinsic.transforms.FitSphericalHarmonics`)
        - **output:** ``entropy`` :math:`(N)`, ``likelihood``
          :math:`(N, \text{grid}[0], \text{grid}[1])`, ``init_specular``
          :math:`(N, 3)`, ``init_base_color`` :math:`(N, 3)`,
          ``init_metallic`` :math:`(N)`, ``init_roughness`` :math:`(N)`
    """
    def __init__(self, grid=(32, 32), sigma: float = 1e-2,
                 store_likelihood: bool = True):
        if not isinstance(grid, (tuple, list)) or len(grid) != 2:
            raise ValueError(f"'grid' must be a pair (specular cells, "
                             f"roughness cells), got {grid!r}")
        self.grid = tuple(check_positive_int(g, 'grid', minimum=2)
                          for g in grid)
        self.sigma = check_positive_float(sigma, 'sigma')
        self.store_likelihood = store_likelihood

    def forward(self, data: Data) -> Data:
        for key in ('sh_in_obs', 'sh_out', 'irradiance', 'sh_prefilter'):
            if getattr(data, key, None) is None:
                raise ValueError(f"SpectralUncertainty needs 'data.{key}'; run "
                                 f"FitSphericalHarmonics first")
        prefilter = float(data.sh_prefilter.reshape(-1)[0])
        spectrum_in, spectrum_out = observed_spectra(data.sh_in_obs,
                                                     data.sh_out)
        entropy, likelihood, roughness, specular = spectral_uncertainty(
            spectrum_in, spectrum_out, self.grid, self.sigma, prefilter)
        diffuse_mean = data.sh_out[:, 0] - specular * data.sh_in_obs[:, 0]
        kd = (math.pi * diffuse_mean / (math.sqrt(4 * math.pi)
                                        * data.irradiance.clamp_min(1e-12))
              ).clamp(0, 1)
        base_color, metallic, roughness = torrance_sparrow_to_principled(
            kd, specular, roughness * roughness)
        data = data.clone()
        data.entropy = entropy
        if self.store_likelihood:
            data.likelihood = likelihood
        data.init_specular = specular
        data.init_base_color = base_color
        data.init_metallic = metallic
        data.init_roughness = roughness
        return data

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(grid={self.grid}, '
                f'sigma={self.sigma})')
