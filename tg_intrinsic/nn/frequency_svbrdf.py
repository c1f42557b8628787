import math
import time
from typing import Callable, Optional, Tuple, Union

import torch
from torch import Tensor
from torch.nn import Parameter
from torch_geometric.data import Data

from tg_intrinsic.geometry import knn, mesh_edges
from tg_intrinsic.geometry.appearance.direct_lighting import (
    direction_visibility, reflection_tables)
from tg_intrinsic.geometry.appearance.envmap import view_lightings
from tg_intrinsic.geometry.appearance.brdf import (
    MIN_ALPHA, dominant_direction, lobe_degree_sums, model_alpha,
    principled_reflectance, principled_reflectance_jacobian, sh_reflectance)
from tg_intrinsic.geometry.appearance.observations import \
    compact_observations
from tg_intrinsic.geometry.appearance.sh import (fit_light,
                                                 light_directions, real_sh,
                                                 smith_g1)
from tg_intrinsic.geometry.checks import (check_choice, check_image_size,
                                           check_index, check_positive_float,
                                           check_positive_int)
from tg_intrinsic.geometry.texture import texture_grid_edges
from tg_intrinsic.nn.svbrdf_result import SVBRDFResult
from tg_intrinsic.solvers.levenberg_marquardt import (
    levenberg_marquardt, levenberg_marquardt_tv)

SOLVERS = ('adam', 'lm')
#: Adam steps, or Levenberg-Marquardt iterations per round, by default.
DEFAULT_STEPS = {'adam': 200, 'lm': 20}
#: Spherical-harmonic degree per specular model in :meth:`recover`: the
#: paper's eq. 5.11 at FitSphericalHarmonics' default, the split sum at 8
#: (its lobe needs the higher bands; benchmarks/svbrdf_accuracy.py).
DEFAULT_L_MAX = {'eq5.11': 5, 'split_sum': 8}
#: Levenberg-Marquardt iterations per round of the refinement.
REFINE_STEPS = 10
#: Most observations per point in the refinement (see
#: :meth:`FrequencySVBRDF.refine`), and the observations it holds in all
#: with ``max_views='auto'``: a capture of more points keeps fewer per
#: point, down to 8 (its time and memory follow the observations: about
#: 30 microseconds and 400 bytes each on 2 CPU cores).
REFINE_MAX_VIEWS = 32
REFINE_OBSERVATIONS = 3_000_000
# Longest Levenberg-Marquardt step of one parameter: the per-point
# objective has a second minimum at a rough dielectric for rough metals
# (and vice versa) that unbounded first steps jump into; measured on the
# model's own observations, 0.05 recovers every point, 0.1 loses 3%.
MAX_STEP = 0.05
#: Parameter difference below which the Levenberg-Marquardt solver treats
#: the total variation as quadratic (Huber): the L1 weights of smaller
#: differences would otherwise glue neighbours together.
TV_EPSILON = 0.02
_NEEDED = ('sh_in', 'mirror_dir', 'irradiance',
           'obs_radiance', 'obs_mask', 'sh_prefilter')


class FrequencySVBRDF(torch.nn.Module):
    r"""Per-point principled SVBRDF parameters with a differentiable
    spherical-harmonic reflection model. The model is eq. 5.11 of
    Wiersma et al., "Uncertainty for SVBRDF Acquisition using Frequency
    Analysis" (SIGGRAPH 2025),

    .. math::
        B(p, \omega_o) = \frac{K_d}{\pi} E(p) + F(\theta_o)\,
        G_\alpha(\theta_o) \sum_{lm} e^{-(\alpha^2 - \alpha'^2) l^2}
        [G_\alpha(\theta_i) L]_{lm}\, Y_{lm}(r),

    with base colour :math:`b`, metallic :math:`m` and roughness
    :math:`\rho` held as parameters (:math:`K_d = b(1 - m)`, :math:`R_0 =
    0.04 + (b - 0.04) m`, :math:`\alpha = \rho^2`), Schlick's :math:`F`,
    Smith's GGX :math:`G_\alpha` as masking (every step) and as shadowing
    of the incoming light (refitted every few steps), and :math:`r` the
    mirror direction of :math:`\omega_o`. :meth:`fit` runs the "mixed"
    recovery: gradient descent on the cosine-weighted L1 distance to all
    observations at once, optionally started from the spectrum grid search
    of :class:`~tg_intrinsic.transforms.SpectralUncertainty`, with an
    optional total-variation term over the surface graph.

    Args:
        num_points (int): Points (or texels) :math:`N`.
        texture_shape (tuple, optional): ``(H, W)`` when the points are
            texels of a texture: all :math:`HW` of them, row by row, or
            those of ``data.texel_index`` (see
            :class:`~tg_intrinsic.transforms.TextureTexels`, which also
            sets ``data.texture_shape``, enough on its own). The total
            variation then runs along the texture grid and exports write
            texture images. (default: :obj:`None`)
        fresnel (bool, optional): Schlick's Fresnel on the specular term.
            (default: :obj:`True`)
        masking (bool, optional): :math:`G_\alpha(\theta_o)`.
            (default: :obj:`True`)
        shadowing (bool, optional): :math:`G_\alpha(\theta_i)` on the light.
            (default: :obj:`True`)
        specular_model (str, optional): :obj:`'eq5.11'` (the paper's model
            above) or :obj:`'split_sum'`: the prefiltered light times the
            exact directional albedo of the GGX lobe,
            :math:`R_0 A(\theta_o, \alpha) + B(\theta_o, \alpha)`, in place
            of :math:`F G_\alpha(\theta_o)` and the shadowing (see
            :func:`~tg_intrinsic.geometry.appearance.brdf.sh_reflectance`).
            (default: :obj:`'eq5.11'`)

    Shapes:
        - **input:** a :class:`~torch_geometric.data.Data` prepared by
          :class:`~tg_intrinsic.transforms.ProjectViews` and
          :class:`~tg_intrinsic.transforms.FitSphericalHarmonics`
        - **output:** predicted radiance :math:`(N, V, 3)`
    """
    def __init__(self, num_points: int, texture_shape=None,
                 fresnel: bool = True, masking: bool = True,
                 shadowing: bool = True, specular_model: str = 'eq5.11'):
        super().__init__()
        self.num_points = check_positive_int(num_points, 'num_points')
        if texture_shape is not None:
            texture_shape = check_image_size(texture_shape, 'texture_shape')
            if math.prod(texture_shape) < num_points:
                raise ValueError(f"'texture_shape' must be (H, W) with H * W "
                                 f">= num_points = {num_points} (the points "
                                 f"are texels), got {texture_shape}")
        self.texture_shape = texture_shape
        self.fresnel, self.masking, self.shadowing = fresnel, masking, \
            shadowing
        self.specular_model = check_choice(specular_model, 'specular_model',
                                           ('eq5.11', 'split_sum'))
        self.base_color = Parameter(torch.empty(num_points, 3))
        self.metallic = Parameter(torch.empty(num_points))
        self.roughness = Parameter(torch.empty(num_points))
        self.reset_parameters()

    def reset_parameters(self):
        """Grey, half metallic, half rough: the original's start."""
        with torch.no_grad():
            for p in self.parameters():
                p.fill_(0.5)

    @torch.no_grad()
    def initialize(self, data: Data, metallic: Optional[float] = None):
        r"""Starts from the argmax of the spectrum grid search
        (``init_base_color``, ``init_metallic``, ``init_roughness``). With a
        known :obj:`metallic` :math:`m > 0`, the base colour follows from
        the specular reflectance instead, :math:`b = (K_s - 0.04 (1 - m)) /
        m`."""
        for name in ('base_color', 'metallic', 'roughness'):
            value = getattr(data, f'init_{name}', None)
            if value is None:
                raise ValueError(f"'data.init_{name}' is missing; run "
                                 f"SpectralUncertainty first")
            getattr(self, name).copy_(value)
        if metallic is not None:
            self.metallic.fill_(metallic)
            specular = getattr(data, 'init_specular', None)
            if metallic > 0 and specular is not None:
                self.base_color.copy_((specular - 0.04 * (1 - metallic))
                                      / metallic)
        self.clamp_()

    @torch.no_grad()
    def clamp_(self):
        r"""Projects the parameters back onto :math:`[0, 1]`, the roughness
        onto :math:`[\sqrt{\alpha_{min}}, 1]`: at 0 the gradient of
        :math:`\alpha = r^2` vanishes and a fit that got there would stay."""
        self.base_color.clamp_(0, 1)
        self.metallic.clamp_(0, 1)
        self.roughness.clamp_(math.sqrt(MIN_ALPHA), 1)

    def shadowed_light(self, data: Data) -> Tensor:
        r"""The incoming SH of :math:`G_\alpha(\theta_i) L` with the current
        roughness (no gradient: refitted every few steps, as the
        original). :math:`G_\alpha` is 0 below the horizon."""
        dtype = data.sh_in.dtype
        if getattr(data, 'light_radiance', None) is None:
            raise ValueError("the shadowing refit needs 'data.light_radiance'"
                             "; run FitSphericalHarmonics with "
                             "store_light_radiance=True (its default), or "
                             "fit with shadowing=False")
        light = data.light_radiance.to(dtype)
        l_max = int(round(math.sqrt(data.sh_in.size(1)))) - 1
        local = light_directions(light.size(1), dtype, light.device)
        alpha = model_alpha(self.roughness.detach().to(dtype))
        shadow = smith_g1(local[:, 2].unsqueeze(0), alpha.unsqueeze(-1))
        regularizer = float(data.sh_regularizer.reshape(-1)[0])
        return fit_light(local, shadow.unsqueeze(-1) * light, l_max,
                         regularizer)

    def forward(self, data: Data, sh_in: Tensor = None,
                basis: Tensor = None) -> Tensor:
        r"""Predicts the radiance of every point towards every view.

        Args:
            data (torch_geometric.data.Data): Prepared by
                :class:`~tg_intrinsic.transforms.ProjectViews` and
                :class:`~tg_intrinsic.transforms.FitSphericalHarmonics`,
                with :math:`N` points and :math:`V` views.
            sh_in (torch.Tensor, optional): The incoming light in spherical
                harmonics per point :math:`(N, K, 3)`, e.g. with the
                shadowing applied; :obj:`None` reads ``data.sh_in``.
                (default: :obj:`None`)
            basis (torch.Tensor, optional): The harmonics :math:`(N, V, K)`
                at the mirror directions (at the lobes' dominant directions
                with :obj:`specular_model='split_sum'`), if already
                computed. (default: :obj:`None`)

        Returns:
            torch.Tensor: The predicted radiance :math:`(N, V, 3)`, in the
            dtype of :obj:`sh_in`.
        """
        self._check(data)
        if sh_in is None:
            sh_in = data.sh_in
        dtype = sh_in.dtype
        return sh_reflectance(
            sh_in, data.irradiance.to(dtype), data.mirror_dir.to(dtype),
            self.base_color.to(dtype), self.metallic.to(dtype),
            self.roughness.to(dtype),
            float(data.sh_prefilter.reshape(-1)[0]), self.fresnel,
            self.masking, self.specular_model,
            None if basis is None else basis.to(dtype))

    def fit(self, data: Data, steps: Optional[int] = None,
            lr: float = 0.01, init: str = 'spectrum',
            shadowing_every: int = 50, tv_weight: float = 0.0,
            tv_k: int = 8, metallic: Optional[float] = None,
            progress: bool = True, solver: str = 'adam',
            rounds: int = 3) -> SVBRDFResult:
        r"""Recovers the parameters from the observations: the
        cosine-weighted L1 distance to all observations, from the spectrum
        grid search (or a constant), by one of two solvers:

        - :obj:`'adam'`: gradient descent on all points at once, the
          original's method, with the shadowing refitted every
          :obj:`shadowing_every` steps.
        - :obj:`'lm'`: every point on its own (the objective is separable,
          5 unknowns per point), by batched projected Levenberg-Marquardt
          (:func:`~tg_intrinsic.solvers.levenberg_marquardt`) with
          iteratively reweighted least squares for the L1 distance; with a
          total variation, all points together. The
          shadowing of the light (or the split sum's lobe directions)
          follows the roughness between :obj:`rounds` solves. It reaches
          a lower objective than Adam in less time, but on captures
          rendered with the full integral its parameters are a little
          further from the truth (the model's error; see the benchmarks).

        Args:
            data (Data): Prepared by ``ProjectViews`` and
                ``FitSphericalHarmonics`` (and ``SpectralUncertainty``,
                which is run here when :obj:`init` needs it and it is
                missing).
            steps (int, optional): Levenberg-Marquardt iterations per round
                (default 20) or Adam steps (default 200); 0 returns the
                initialisation (the "spectrum-only" recovery with
                :obj:`init='spectrum'`). (default: :obj:`None`)
            lr (float, optional): Adam learning rate. (default: :obj:`0.01`)
            init (str, optional): :obj:`'spectrum'` (grid-search argmax) or
                :obj:`'constant'` (0.5 everywhere). (default:
                :obj:`'spectrum'`)
            shadowing_every (int, optional): Adam steps between shadowing
                refits. (default: :obj:`50`)
            tv_weight (float, optional): Weight of the total variation
                :math:`\frac{1}{|E|}\sum_{(i,j)} |x_i - x_j|` over the
                4-neighbour grid of the texels for texture points
                (:func:`~tg_intrinsic.geometry.texture.texture_grid_edges`),
                else mesh edges (or a :obj:`tv_k`-nearest-neighbour graph);
                with :obj:`'lm'` it couples the points, which are then
                solved together
                (:func:`~tg_intrinsic.solvers.levenberg_marquardt_tv`).
                (default: :obj:`0.0`)
            tv_k (int, optional): Neighbours of that graph for point
                clouds. (default: :obj:`8`)
            metallic (float, optional): Holds the metallic map at this
                value instead of fitting it, for captures whose material
                class is known (1 for metals, 0 for dielectrics): it
                removes the diffuse / specular ambiguity that otherwise
                leaks into the base colour. (default: :obj:`None`)
            progress (bool, optional): Show a progress bar.
                (default: :obj:`True`)
            solver (str, optional): :obj:`'lm'` or :obj:`'adam'`.
                (default: :obj:`'adam'`)
            rounds (int, optional): Levenberg-Marquardt solves, with the
                shadowing refitted before each. (default: :obj:`3`)

        Returns:
            :class:`~tg_intrinsic.nn.svbrdf_result.SVBRDFResult`.
        """
        solver = check_choice(solver, 'solver', SOLVERS)
        if steps is None:
            steps = DEFAULT_STEPS[solver]
        steps = check_positive_int(steps, 'steps', minimum=0)
        lr = check_positive_float(lr, 'lr')
        shadowing_every = check_positive_int(shadowing_every,
                                             'shadowing_every')
        rounds = check_positive_int(rounds, 'rounds')
        tv_weight = check_positive_float(tv_weight, 'tv_weight',
                                         allow_zero=True)
        check_choice(init, 'init', ('spectrum', 'constant'))
        self._check_metallic(metallic)
        self._check(data)
        if view_lightings(data) is not None:
            raise ValueError(
                "fit models one lighting, but the views of this capture are "
                "lit by several maps ('data.envmaps'); refine (the full "
                "integral) takes each view's own map, or fit each "
                "lighting's views on their own and merge the results "
                "(SVBRDFResult.merge_by_uncertainty)")
        self._texels(data)  # validated before the work
        self._check_observations(data)
        start = time.perf_counter()
        if getattr(data, 'init_roughness', None) is None \
                or getattr(data, 'entropy', None) is None:
            from tg_intrinsic.transforms.spectral_uncertainty import \
                SpectralUncertainty
            data = SpectralUncertainty(store_likelihood=False)(data)
        if init == 'spectrum':
            self.initialize(data, metallic)
        else:
            self.reset_parameters()
            if metallic is not None:
                with torch.no_grad():
                    self.metallic.fill_(metallic)
        self.to(data.sh_in.device)
        problem = _Problem(self, data, tv_weight, tv_k)
        if solver == 'lm':
            history = self._fit_lm(problem, steps, rounds, metallic,
                                   progress)
        else:
            history = self._fit_adam(problem, steps, lr, shadowing_every,
                                     metallic, progress)
        return self._result(problem, history, start,
                            fixed_metallic=metallic is not None)

    def refine(self, data: Data, envmap: Optional[Tensor] = None,
               steps: int = REFINE_STEPS, rounds: int = 2,
               tv_weight: float = 0.0,
               tv_k: int = 8, metallic: Optional[float] = None,
               visibility: str = 'auto', roughness_cells: int = 17,
               light_samples: int = 64, brdf_samples: int = 32,
               seed: int = 0, metallic_starts: bool = True,
               max_views: Union[int, str, None] = 'auto',
               progress: bool = True) -> SVBRDFResult:
        r"""Refines the current parameters (usually those of :meth:`fit`)
        against the observations with the full reflection integral of
        direct environment lighting instead of the spherical-harmonic
        model, the chapter's "initialisation" application:

        .. math::
            B(\mathbf{p}, \omega_o) = \frac{K_d}{\pi} E(\mathbf{p})
            + R_0\, A(\mathbf{p}, \omega_o; r)
            + C(\mathbf{p}, \omega_o; r),

        with the shadowed irradiance :math:`E` and the specular integrals
        :math:`A, C` of GGX + Smith + Schlick over the whole environment
        map, tabulated once over :obj:`roughness_cells` roughness values
        for every observed pair
        (:func:`~tg_intrinsic.geometry.appearance.direct_lighting.reflection_tables`;
        torch, CPU or GPU), and visibility from the geometry. The same
        cosine-weighted L1 distance as :meth:`fit` is minimised by the
        batched Levenberg-Marquardt solver.

        Args:
            data (Data): As for :meth:`fit`, with ``normal`` and
                ``obs_dir``.
            envmap (torch.Tensor, optional): The light :math:`(H, W, 3)`
                (default ``data.envmap``). (default: :obj:`None`)
            steps (int, optional): Iterations per round. (default: :obj:`10`)
            rounds (int, optional): Solves, each from the last, the
                damping reset (one stopped early on the command's example
                capture: base RMSE 0.080 against 0.041 with two).
                (default: :obj:`2`)
            tv_weight (float, optional): As for :meth:`fit`.
                (default: :obj:`0.0`)
            tv_k (int, optional): As for :meth:`fit`. (default: :obj:`8`)
            metallic (float, optional): As for :meth:`fit`.
                (default: :obj:`None`)
            metallic_starts (bool, optional): With the metallic map free,
                start every point from the better (by its data loss) of
                its current parameters and the best cell of a search over
                the tables: a pure dielectric or a pure metal at each
                tabulated roughness, its colour by least squares. The
                objective has a second minimum along the metallic axis (a
                rough dielectric for a rough metal, and vice versa) that
                one local solve from the spherical-harmonic fit does not
                leave. (default: :obj:`True`)
            visibility (str, optional): :obj:`'geometry'` (rays against the
                mesh: ``face`` over the points, or ``mesh_pos`` /
                ``mesh_face`` that texels were cut from; needs one),
                :obj:`'horizon'` (every direction above the tangent plane:
                convex objects) or :obj:`'auto'` (geometry when there is a
                mesh). (default: :obj:`'auto'`)
            roughness_cells (int, optional): Roughness values of the tables,
                evenly spaced from :math:`\sqrt{\alpha_{min}}` to 1 (25
                changed the errors by at most 0.002 on 2562 points x 25
                views and took 20-25% longer). (default: :obj:`17`)
            light_samples (int, optional): Environment samples per point.
                (default: :obj:`64`)
            brdf_samples (int, optional): GGX samples per pair and
                roughness. (default: :obj:`32`)
            seed (int, optional): Seed of the integration samples.
                (default: :obj:`0`)
            max_views (int or str, optional): Most observations per point
                in the tables and the solve (its brightest quarter and the
                views that cover its reflections best, see
                :func:`~tg_intrinsic.geometry.appearance.observations.observed_slots`);
                :obj:`None` takes every one; :obj:`'auto'`
                :data:`REFINE_MAX_VIEWS`, fewer (down to 8) where the
                points would hold more than :data:`REFINE_OBSERVATIONS`
                in all. The cost and memory of the refinement follow the
                observations it holds. (default: :obj:`'auto'`)
            progress (bool, optional): Show a progress bar.
                (default: :obj:`True`)

        Returns:
            :class:`~tg_intrinsic.nn.svbrdf_result.SVBRDFResult`, its
            ``seconds`` including the tables, and its ``pipeline`` the
            seconds of the visibility, the tables and the solve.
        """
        steps = check_positive_int(steps, 'steps', minimum=0)
        rounds = check_positive_int(rounds, 'rounds')
        tv_weight = check_positive_float(tv_weight, 'tv_weight',
                                         allow_zero=True)
        roughness_cells = check_positive_int(roughness_cells,
                                             'roughness_cells', minimum=2)
        visibility = check_choice(visibility, 'visibility',
                                  ('auto', 'geometry', 'horizon'))
        self._check_metallic(metallic)
        self._check(data)
        self._texels(data)
        for key in ('normal', 'obs_dir'):
            if getattr(data, key, None) is None:
                raise ValueError(f"'data.{key}' is missing; prepare the data "
                                 f"with ProjectViews")
        # one lighting (envmap, data.envmap) or one per view (data.envmaps)
        lightings = None if envmap is not None else view_lightings(data)
        if envmap is None and lightings is None:
            envmap = getattr(data, 'envmap', None)
            if envmap is None:
                raise ValueError("refine needs the light: pass 'envmap' or "
                                 "set 'data.envmap' [H, W, 3]")
        self._check_observations(data)
        start = time.perf_counter()
        # per point, the views that see it: (N, K) in place of (N, V)
        if max_views == 'auto':
            max_views = min(REFINE_MAX_VIEWS, max(
                8, REFINE_OBSERVATIONS // max(data.num_nodes, 1)))
        data = compact_observations(data, max_views)
        if metallic is not None:
            with torch.no_grad():
                self.metallic.fill_(metallic)
        # the occluding mesh: the points' own, or the one their texels
        # were cut from (TextureTexels)
        if getattr(data, 'face', None) is not None:
            mesh = data.pos, data.face
        elif getattr(data, 'mesh_face', None) is not None:
            mesh = data.mesh_pos, data.mesh_face
        else:
            mesh = None
        if visibility == 'geometry' and mesh is None:
            raise ValueError("visibility='geometry' needs the mesh in "
                             "'data.face' (or 'data.mesh_pos' / "
                             "'data.mesh_face' of texels); use 'horizon' "
                             "for point clouds")
        dtype = data.sh_in.dtype
        parts = {}
        visible = None
        if mesh is not None and visibility != 'horizon':
            visible = direction_visibility(data.pos, data.normal, *mesh)
        parts['visibility'] = time.perf_counter() - start
        grid = torch.linspace(math.sqrt(MIN_ALPHA), 1.0, roughness_cells,
                              dtype=dtype, device=data.sh_in.device)
        # single precision: the tables are Monte Carlo estimates (about 1%
        # noise), and float32 halves their cost
        irradiance, tables = _lit_tables(
            data, envmap, lightings, grid.to(torch.float32), visible,
            light_samples, brdf_samples, seed)
        parts['tables'] = time.perf_counter() - start - parts['visibility']
        # the tables stay single precision (half the memory of the largest
        # array of a refinement); what is read of them is cast to dtype
        problem = _IntegralProblem(self, data, tv_weight, tv_k, grid,
                                   irradiance.to(dtype), tables)
        if metallic is None and metallic_starts and steps > 0:
            history = self._fit_metallic_starts(problem, steps, rounds,
                                                progress)
        else:
            history = self._fit_lm(problem, steps, rounds, metallic,
                                   progress)
        result = self._result(problem, history, start,
                              fixed_metallic=metallic is not None)
        parts['solve'] = result.seconds - parts['visibility'] - \
            parts['tables']
        result.pipeline = {'seconds': {
            key: round(value, 3) for key, value in parts.items()},
            'max_views': max_views,
            'observations': int(data.obs_mask.sum())}
        return result

    def recover(self, data: Data, refine: Union[str, bool] = 'auto',
                visibility: str = 'auto', solver: Optional[str] = None,
                steps: Optional[int] = None,
                refine_steps: int = REFINE_STEPS,
                l_max: Optional[int] = None, tv_weight: float = 0.02,
                metallic: Optional[float] = None,
                log: Optional[Callable[[str], None]] = None,
                progress: bool = True) -> Tuple[SVBRDFResult, Data]:
        r"""The whole recovery, with the lowest error this library reaches
        by default: the steps ``data`` still lacks (projection into the
        views, :class:`~tg_intrinsic.transforms.ProjectViews`; the
        spherical-harmonic fits,
        :class:`~tg_intrinsic.transforms.FitSphericalHarmonics`; the
        spectrum grid search and entropy,
        :class:`~tg_intrinsic.transforms.SpectralUncertainty`), then

        - with the refinement (whenever the capture allows it: the
          environment map, and a mesh for the visibility or
          :obj:`visibility='horizon'` for a convex object), :meth:`refine`
          from the spectrum's start. A spherical-harmonic :meth:`fit`
          before it changed the maps by at most 0.002 on the benchmark's
          captures and adds about a second, so it runs only when
          :obj:`solver` or :obj:`steps` ask for it;
        - without it, :meth:`fit` (Levenberg-Marquardt unless
          :obj:`solver` says otherwise): the paper's recovery.

        A capture whose photographs are lit by different maps
        (``data.envmaps`` with ``data.view_lighting``, e.g. from
        :func:`~tg_intrinsic.transforms.join_lightings` or a
        ``transforms.json`` with ``hdri_path``) gets its harmonics and
        spectra per lighting, each point starts from the lighting of lowest
        entropy, and the refinement (required) takes every view under its
        own map.

        Args:
            data (Data): A capture as :func:`~tg_intrinsic.io.read_scene`
                or :func:`~tg_intrinsic.datasets.svbrdf_scene` returns it
                (photographs and cameras, or observations), on any device.
            refine (str or bool, optional): :obj:`'auto'` (when the capture
                allows it), :obj:`True` (an error when it does not) or
                :obj:`False` (the spherical-harmonic recovery alone).
                (default: :obj:`'auto'`)
            visibility (str, optional): As for :meth:`refine`; with
                :obj:`'auto'`, a point cloud without a mesh is not refined
                (its occlusion is unknown). (default: :obj:`'auto'`)
            solver (str, optional): Solver of :meth:`fit`; :obj:`None`:
                :obj:`'lm'`, and no fit before a refinement.
                (default: :obj:`None`)
            steps (int, optional): Steps of :meth:`fit`. (default:
                :obj:`None`, the solver's)
            refine_steps (int, optional): Iterations per round of
                :meth:`refine`. (default: :obj:`10`)
            l_max (int, optional): Degree of the spherical harmonics when
                they are fitted here; :obj:`None`: :data:`DEFAULT_L_MAX` of
                the specular model. (default: :obj:`None`)
            tv_weight (float, optional): As for :meth:`fit`, in the units of
                the observed radiance (the default suits radiance of order
                1; scale it with the exposure). (default: :obj:`0.02`)
            metallic (float, optional): As for :meth:`fit`.
                (default: :obj:`None`)
            log (callable, optional): Called with a line when a step starts
                and when it ends (with its time). (default: :obj:`None`)
            progress (bool, optional): Progress bars of the solvers.
                (default: :obj:`True`)

        Returns:
            ``(result, data)``: the
            :class:`~tg_intrinsic.nn.svbrdf_result.SVBRDFResult`, whose
            ``pipeline`` says which steps ran, their seconds, the first
            and last loss of the fit and the refinement, the visibility
            and, when the refinement did not run, why; and the
            capture with what the steps computed (observations, harmonics,
            entropy).
        """
        from tg_intrinsic.transforms import (FitSphericalHarmonics,
                                             ProjectViews,
                                             SpectralUncertainty)
        if refine not in ('auto', True, False):
            raise ValueError(f"'refine' must be 'auto', True or False, got "
                             f"{refine!r}")
        visibility = check_choice(visibility, 'visibility',
                                  ('auto', 'geometry', 'horizon'))
        if solver is not None:
            check_choice(solver, 'solver', SOLVERS)
        refine_steps = check_positive_int(refine_steps, 'refine_steps',
                                          minimum=0)
        if l_max is None:
            l_max = DEFAULT_L_MAX[self.specular_model]
        self._check_metallic(metallic)
        has_mesh = getattr(data, 'face', None) is not None or \
            getattr(data, 'mesh_face', None) is not None
        reason = None
        lightings = view_lightings(data)
        if getattr(data, 'envmap', None) is None and lightings is None:
            reason = "the capture has no environment map ('data.envmap')"
        elif not has_mesh and visibility != 'horizon':
            reason = ("a point cloud without a mesh, whose occlusion is "
                      "unknown (a convex object can be refined with the "
                      "horizon visibility)")
        elif refine_steps == 0:
            reason = 'refine_steps is 0'
        if lightings is not None:
            several = ("the views are lit by several maps ('data.envmaps'),"
                       " which only the refinement models")
            if refine is False or reason is not None:
                raise ValueError(f"{several}, and it cannot run: "
                                 f"{reason or 'not asked for'}")
            if solver is not None or steps is not None:
                raise ValueError(f"{several}; the spherical-harmonic fit "
                                 f"(solver, steps) does not apply")
        if refine is True and reason is not None:
            raise ValueError(f"the refinement cannot run: {reason}")
        refining = refine is not False and reason is None
        if refine is False:
            reason = 'not asked for'
        seconds = {}

        def step(description, key, function):
            if log is not None:
                log(f'{description} ...')
            begin = time.perf_counter()
            out = function()
            seconds[key] = round(time.perf_counter() - begin, 3)
            if log is not None:
                log(f'{description}: {seconds[key]:.2f} s')
            return out
        start = time.perf_counter()
        if getattr(data, 'obs_radiance', None) is None:
            data = step('projecting the points into the views', 'project',
                        lambda: ProjectViews()(data))
        if lightings is not None and getattr(data, 'sh_in', None) is None:
            # the spectra of each lighting's views; each point starts from
            # the lighting whose spectrum is the most certain (lowest
            # entropy), then the refinement takes every view under its map
            parts = step(f'fitting spherical harmonics per lighting (l_max '
                         f'= {l_max})', 'fit_spherical_harmonics',
                         lambda: [(views, FitSphericalHarmonics(
                             l_max=l_max, store_light_radiance=False)(part))
                             for views, part in
                             _one_lighting_captures(data, lightings)])
            data = step('spectral uncertainty per lighting',
                        'spectral_uncertainty',
                        lambda: _lowest_entropy_start(data, [
                            (views, SpectralUncertainty(
                                store_likelihood=False)(part))
                            for views, part in parts]))
        fitting = not refining or solver is not None or steps is not None
        # the light samples serve the shadowing refit of fit() alone
        harmonics = FitSphericalHarmonics(l_max=l_max,
                                          store_light_radiance=fitting)
        if getattr(data, 'sh_in', None) is None:
            data = step(f'fitting spherical harmonics (l_max = {l_max})',
                        'fit_spherical_harmonics', lambda: harmonics(data))
        if getattr(data, 'entropy', None) is None or \
                getattr(data, 'init_roughness', None) is None:
            data = step('spectral uncertainty', 'spectral_uncertainty',
                        lambda: SpectralUncertainty(
                            store_likelihood=False)(data))
        solver = 'lm' if solver is None else solver
        steps = DEFAULT_STEPS[solver] if steps is None else steps
        loss = {}
        if fitting:
            result = step(f'fitting ({solver}, {steps} steps)', 'fit',
                          lambda: self.fit(data, steps=steps, solver=solver,
                                           tv_weight=tv_weight,
                                           metallic=metallic,
                                           progress=progress))
            loss['fit'] = [result.loss[0], result.loss[-1]]
        else:
            self.to(data.sh_in.device)
            self.initialize(data, metallic)
        if refining:
            result = step(f'refining against the full integral '
                          f'({refine_steps} steps)', 'refine',
                          lambda: self.refine(data, steps=refine_steps,
                                              tv_weight=tv_weight,
                                              metallic=metallic,
                                              visibility=visibility,
                                              progress=progress))
            loss['refine'] = [result.loss[0], result.loss[-1]]
            refine_parts = result.pipeline
        result.seconds = time.perf_counter() - start
        result.pipeline = {
            'steps': list(seconds), 'seconds': seconds,
            'fit': {'solver': solver, 'steps': steps} if fitting else None,
            'refine': {'steps': refine_steps,
                       'visibility': 'geometry' if has_mesh
                       and visibility != 'horizon' else 'horizon',
                       **refine_parts}
            if refining else None,
            'not_refined_because': None if refining else reason,
            'loss': loss,
            'l_max': int(round(math.sqrt(data.sh_in.size(1)))) - 1}
        return result, data

    def _fit_metallic_starts(self, problem, steps, rounds, progress):
        """Per point, the better of the current parameters and the best
        cell of a search over the tables (a pure dielectric or a pure metal
        at each tabulated roughness, the base colour by least squares),
        then the solves: the metallic axis has a second minimum (a rough
        dielectric for a rough metal, and vice versa) that a local solve
        from the SH fit does not leave."""
        with torch.no_grad():
            candidate = problem.table_search()
            current = (self.base_color, self.metallic, self.roughness)
            better = problem.point_loss(*candidate) < problem.point_loss(
                *current)
            for parameter, value in zip(current, candidate):
                parameter.copy_(torch.where(
                    better.view(-1, *[1] * (value.dim() - 1)), value,
                    parameter))
        return self._fit_lm(problem, steps, rounds, None, progress)

    def _result(self, problem, history, start,
                fixed_metallic: bool) -> SVBRDFResult:
        with torch.no_grad():
            final = float(problem.loss(self.base_color, self.metallic,
                                       self.roughness))
        texture_shape, texel_index = self._texels(problem.data)
        return SVBRDFResult(
            base_color=self.base_color.detach().clone(),
            metallic=self.metallic.detach().clone(),
            roughness=self.roughness.detach().clone(),
            entropy=getattr(problem.data, 'entropy', None),
            roughness_std=problem.roughness_std(fixed_metallic),
            loss=history + [final], seconds=time.perf_counter() - start,
            texture_shape=texture_shape, texel_index=texel_index)

    def _fit_adam(self, problem, steps, lr, shadowing_every, metallic,
                  progress):
        from tqdm.auto import tqdm
        fitted = [self.base_color, self.roughness]
        if metallic is None:
            fitted.append(self.metallic)
        optimizer = torch.optim.Adam(fitted, lr=lr)
        history = []
        for step in tqdm(range(steps), disable=not progress,
                         desc='FrequencySVBRDF'):
            if step % shadowing_every == 0:
                problem.refresh()
            loss = problem.objective()
            if not bool(torch.isfinite(loss)):
                raise RuntimeError(f"the loss became {float(loss)} at step "
                                   f"{step}; check the observations for "
                                   f"NaN/inf radiance or lower 'lr'")
            self.zero_grad()
            loss.backward()
            optimizer.step()
            self.clamp_()
            history.append(float(loss.detach()))
        if steps == 0:
            problem.refresh()
        return history

    def _fit_lm(self, problem, steps, rounds, metallic, progress):
        from tqdm.auto import tqdm
        # unknowns: base colour (3), metallic unless held, roughness
        columns = [0, 1, 2, 4] if metallic is not None else [0, 1, 2, 3, 4]
        lower = torch.tensor([0.0, 0.0, 0.0, 0.0, math.sqrt(MIN_ALPHA)]
                             )[columns]
        history = []
        for _ in tqdm(range(rounds if steps > 0 else 0),
                      disable=not progress, desc='FrequencySVBRDF'):
            problem.refresh()
            with torch.no_grad():
                history.append(float(problem.objective()))
                every = torch.cat([self.base_color,
                                   self.metallic.unsqueeze(-1),
                                   self.roughness.unsqueeze(-1)], 1)
            x0 = every[:, columns].to(problem.dtype)
            residual, jacobian = problem.residual(columns)
            bounds = lower.to(x0), torch.ones_like(lower).to(x0)
            options = dict(max_iter=steps, tol=1e-4, max_step=MAX_STEP,
                           l1_epsilon=1e-3 * problem.radiance_scale)
            if problem.edges is None:  # every point on its own
                x, _ = levenberg_marquardt(
                    residual, x0, problem.weight_rows, *bounds, loss='l1',
                    jacobian=jacobian, **options)
            else:  # coupled by the total variation
                x, _ = levenberg_marquardt_tv(
                    jacobian, x0, problem.weight_rows, problem.edges,
                    problem.tv_weight / problem.edges.size(1), *bounds,
                    tv_epsilon=TV_EPSILON, rows_per_call=LM_ROWS, **options)
            with torch.no_grad():
                every[:, columns] = x.to(every)
                self.base_color.copy_(every[:, :3])
                self.metallic.copy_(every[:, 3])
                self.roughness.copy_(every[:, 4])
        if not history:
            problem.refresh()
        return history

    def _basis(self, data: Data, l_max: int) -> Tensor:
        """Harmonics at the mirror directions (eq. 5.11) or at the lobes'
        dominant directions (split sum), which move slowly with the
        roughness and are refreshed like the shadowing, without a
        gradient."""
        direction = data.mirror_dir
        if self.specular_model == 'split_sum':
            direction = dominant_direction(direction, self.roughness.detach(
            ).to(direction.dtype))
        return real_sh(direction, l_max)

    def total_variation(self, edges: Tensor) -> Tensor:
        """Mean absolute difference of all parameters across edges."""
        i, j = edges
        tv = (self.base_color[i] - self.base_color[j]).abs().sum(-1)
        tv = tv + (self.metallic[i] - self.metallic[j]).abs()
        tv = tv + (self.roughness[i] - self.roughness[j]).abs()
        return tv.mean()

    def _graph(self, data: Data, k: int) -> Tensor:
        """The total variation's graph: the texture grid among texels,
        else the mesh edges, else a kNN graph."""
        texture_shape, texel_index = self._texels(data)
        if texture_shape is not None:
            if texel_index is None:  # every texel, row by row
                texel_index = torch.arange(self.num_points,
                                           device=data.sh_in.device)
            return texture_grid_edges(texel_index, texture_shape)
        face = getattr(data, 'face', None)
        if face is not None:
            return mesh_edges(face, data.pos.size(0))
        return knn(data.pos, k)

    def _texels(self, data: Data):
        """``(texture_shape, texel_index)`` when the points are texels (the
        model's or the data's texture; the index is None when the points
        are all texels in order), else ``(None, None)``."""
        shape = self.texture_shape
        given = getattr(data, 'texture_shape', None)
        if given is not None:
            given = check_image_size(tuple(int(s) for s in given),
                                     'data.texture_shape')
            if shape is not None and shape != given:
                raise ValueError(f"the model's texture_shape {shape} differs "
                                 f"from 'data.texture_shape' {given}")
            shape = given
        index = getattr(data, 'texel_index', None)
        if shape is None:
            if index is not None:
                raise ValueError("'data.texel_index' needs a texture: set "
                                 "'data.texture_shape' or the model's "
                                 "texture_shape")
            return None, None
        if index is None:
            if math.prod(shape) != self.num_points:
                raise ValueError(f"{self.num_points} points are not all "
                                 f"texels of a {shape} texture; give "
                                 f"'data.texel_index' (see TextureTexels)")
            return shape, None
        index = check_index(index, 'data.texel_index', math.prod(shape),
                            data.sh_in, size=self.num_points,
                            what='texels (H * W)', ref_name='data.sh_in')
        if torch.unique(index).numel() != index.numel():
            raise ValueError("'data.texel_index' repeats texels; every point "
                             "must be a different texel")
        return shape, index

    @staticmethod
    def _check_metallic(metallic):
        if metallic is not None and not (isinstance(metallic, (int, float))
                                         and 0 <= metallic <= 1):
            raise ValueError(f"'metallic' must be None (fitted) or a number "
                             f"in [0, 1], got {metallic!r}")

    @staticmethod
    def _check_observations(data: Data):
        observed = data.obs_radiance[data.obs_mask.bool()]
        if observed.numel() == 0:
            raise ValueError("no point is observed by any view "
                             "('data.obs_mask' is all False): check the "
                             "cameras, they must look at the object")
        if not bool(torch.isfinite(observed).all()):
            raise ValueError("'data.obs_radiance' holds NaN or infinite "
                             "radiance at observed entries; mask them out "
                             "in 'obs_mask' (ProjectViews does so for NaN "
                             "pixels)")

    def _check(self, data: Data):
        for key in _NEEDED:
            if getattr(data, key, None) is None:
                raise ValueError(f"'data.{key}' is missing; prepare the data "
                                 f"with ProjectViews and "
                                 f"FitSphericalHarmonics")
        if data.sh_in.size(0) != self.num_points:
            raise ValueError(f"the model holds {self.num_points} points but "
                             f"the data has {data.sh_in.size(0)}")

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}({self.num_points}, '
                f'texture_shape={self.texture_shape}, fresnel={self.fresnel}, '
                f'masking={self.masking}, shadowing={self.shadowing}, '
                f'specular_model={self.specular_model!r})')


class _Problem:
    """The fitting problem of one capture: targets and weights of the
    observations, the light's degree sums at the current shadowing (or
    split-sum lobe directions), and the total-variation graph."""
    def __init__(self, model: FrequencySVBRDF, data: Data, tv_weight: float,
                 tv_k: int):
        self.model, self.data = model, data
        self.dtype = data.sh_in.dtype
        mask = data.obs_mask.bool()
        self.weight = (data.mirror_dir[..., 2].clamp_min(0) * mask
                       ).unsqueeze(-1).to(self.dtype)
        self.target = torch.where(mask.unsqueeze(-1), data.obs_radiance,
                                  torch.zeros_like(data.obs_radiance)
                                  ).to(self.dtype)
        self.normaliser = 3 * self.weight.sum().clamp_min(1e-30)
        seen = self.target[mask]
        self.radiance_scale = float(seen.abs().mean()) if seen.numel() \
            else 1.0
        self.l_max = int(round(math.sqrt(data.sh_in.size(1)))) - 1
        self.tv_weight, self.tv_k = tv_weight, tv_k
        self.edges = model._graph(data, tv_k) if tv_weight > 0 \
            else None
        # the residuals' weights, one row per point, as the solvers take them
        self.weight_rows = (self.weight.expand_as(self.target)
                            / self.normaliser).reshape(self.target.size(0),
                                                       -1)
        self.sums = None

    def refresh(self):
        """Degree sums with the shadowing (eq. 5.11) or the lobe directions
        (split sum) of the current roughness, held fixed until the next
        refresh, as the original refits its shadowing."""
        model, data = self.model, self.data
        sh_in = data.sh_in
        if model.specular_model == 'eq5.11' and model.shadowing:
            sh_in = model.shadowed_light(data)
        self.sums = lobe_degree_sums(sh_in, model._basis(data, self.l_max))

    def predict(self, base_color, metallic, roughness, rows=None,
                jacobian: bool = False):
        data, model = self.data, self.model
        take = (lambda t: t) if rows is None else (lambda t: t[rows])
        function = principled_reflectance_jacobian if jacobian \
            else principled_reflectance
        return function(
            take(self.sums), take(data.irradiance).to(self.dtype),
            take(data.mirror_dir).to(self.dtype), base_color.to(self.dtype),
            metallic.to(self.dtype), roughness.to(self.dtype),
            float(data.sh_prefilter.reshape(-1)[0]), model.fresnel,
            model.masking, model.specular_model)

    def loss(self, base_color, metallic, roughness):
        return self.point_loss(base_color, metallic, roughness).sum()

    def point_loss(self, base_color, metallic, roughness) -> Tensor:
        """Each point's share of the data loss :math:`(N,)`."""
        error = self.predict(base_color, metallic, roughness) - self.target
        return (self.weight * error.abs()).sum((1, 2)) / self.normaliser

    def objective(self) -> Tensor:
        """The model's data loss plus its total variation, if any."""
        model = self.model
        loss = self.loss(model.base_color, model.metallic, model.roughness)
        if self.edges is not None:
            loss = loss + self.tv_weight * model.total_variation(self.edges)
        return loss

    def roughness_std(self, fixed_metallic: bool) -> Tensor:
        r"""The estimated standard deviation of every point's roughness
        at the current parameters :math:`(N)`,
        :math:`s_i = \sqrt{v_i + d_i^2}`, clamped to 1 (the whole range;
        also the value of points with no more observations than
        unknowns): the sampling variance :math:`v_i` of the point's
        weighted L1 fit (:meth:`roughness_variance`) and the mean absolute
        roughness difference :math:`d_i` to its neighbours
        (:meth:`neighbour_spread`), which grows where the smoothing meets
        a change that the data do not settle."""
        variance = self.roughness_variance(fixed_metallic)
        std = (variance + self.neighbour_spread() ** 2).sqrt()
        return torch.where(torch.isfinite(std), std.clamp(max=1.0),
                           torch.ones_like(std))

    def roughness_variance(self, fixed_metallic: bool) -> Tensor:
        r"""The asymptotic variance of the roughness of each point's
        weighted L1 fit (an M-estimator's sandwich), its residuals
        :math:`e_k` taken as independent Gaussian noise of one scale per
        point,

        .. math::
            \operatorname{Cov} = \frac{\pi \hat\sigma_i^2}{2}\,
            A^{-1} B A^{-1}, \quad A = \sum_k w_k \mathbf{J}_k^\top
            \mathbf{J}_k, \quad B = \sum_k w_k^2 \mathbf{J}_k^\top
            \mathbf{J}_k, \quad \hat\sigma_i^2 = \frac{\pi}{2}
            \frac{n_i}{n_i - p} \Big(\frac{\sum_k w_k |e_k|}{\sum_k w_k}
            \Big)^2

        (:math:`\pi \sigma^2 / 2 = 1 / (4 f(0)^2)` for a Gaussian density
        :math:`f`; :math:`n_i` observed values, :math:`p` unknowns), its
        roughness entry :math:`(N)`; infinite where :math:`n_i \le p`."""
        model = self.model
        columns = [0, 1, 2, 4] if fixed_metallic else [0, 1, 2, 3, 4]
        num, unknowns = self.target.size(0), len(columns)
        with torch.no_grad():
            pred, jac = self.predict(model.base_color, model.metallic,
                                     model.roughness, jacobian=True)
            error = (pred - self.target).reshape(num, -1).abs()
            jac = jac[..., columns].reshape(num, -1, unknowns)
            weight = self.weight.expand_as(self.target).reshape(num, -1)
            weight = weight / weight.amax(1, keepdim=True).clamp_min(1e-300)
            # in float64: a relative ridge of 1e-9 is below float32's
            # resolution, and a point seen fewer times than it has unknowns
            # then has an exactly singular matrix
            outer = torch.einsum('nki,nkj->nkij', jac.double(), jac.double())
            a = torch.einsum('nk,nkij->nij', weight.double(), outer)
            b = torch.einsum('nk,nkij->nij', weight.double() ** 2, outer)
            # a relative ridge: directions no observation sees stay unknown
            # instead of failing the inverse
            ridge = 1e-9 * a.diagonal(dim1=1, dim2=2).mean(1) + 1e-300
            a_inverse = torch.linalg.inv(a + ridge.view(-1, 1, 1) * torch.eye(
                unknowns, dtype=a.dtype, device=a.device))
            sandwich = (a_inverse @ b @ a_inverse)[:, -1, -1].clamp_min(0)
            observed = (weight > 0).sum(1).to(a.dtype)
            mean_error = (weight * error).sum(1) / weight.sum(1).clamp_min(
                1e-300)
            sigma2 = math.pi / 2 * mean_error ** 2 * observed / (
                observed - unknowns).clamp_min(1e-300)
            variance = math.pi / 2 * sigma2 * sandwich
            return torch.where(observed > unknowns, variance,
                               torch.full_like(variance, math.inf)
                               ).to(weight.dtype)

    def neighbour_spread(self) -> Tensor:
        r"""Each point's mean absolute roughness difference to its
        neighbours in the total variation's graph (built for this when
        the fit had no total variation)
        :math:`d_i = \frac{1}{|\mathcal{N}(i)|} \sum_{j \in
        \mathcal{N}(i)} |r_i - r_j|` :math:`(N)`."""
        edges = self.edges if self.edges is not None \
            else self.model._graph(self.data, self.tv_k)
        i, j = edges
        roughness = self.model.roughness.detach().to(self.dtype)
        difference = (roughness[i] - roughness[j]).abs()
        # both ends: the same for a graph that holds both directions
        total = torch.zeros_like(roughness).index_add_(
            0, i, difference).index_add_(0, j, difference)
        count = torch.zeros_like(roughness).index_add_(
            0, i, torch.ones_like(difference)).index_add_(
                0, j, torch.ones_like(difference))
        return total / count.clamp_min(1)

    def residual(self, columns):
        """The residuals of the points ``rows`` at parameters ``x``, the
        ``columns`` of (base colour, metallic, roughness) that are fitted,
        and a function that also returns their Jacobian."""
        metallic = self.model.metallic.detach().to(self.dtype)
        fixed_metallic = 3 not in columns

        def arguments(x, rows):
            m = metallic[rows] if fixed_metallic else x[:, 3]
            return x[:, :3], m, x[:, -1], rows

        def residual(x, rows):
            pred = self.predict(*arguments(x, rows))
            return (pred - self.target[rows]).reshape(rows.numel(), -1)

        def jacobian(x, rows):
            pred, jac = self.predict(*arguments(x, rows), jacobian=True)
            n = rows.numel()
            return ((pred - self.target[rows]).reshape(n, -1),
                    jac[..., columns].reshape(n, -1, len(columns)))
        return residual, jacobian


#: Points whose residuals and Jacobian the coupled solve evaluates at
#: once (the whole Jacobian of 250k points x 12 observations is 360 MB in
#: float64, and its temporaries several times that).
LM_ROWS = 16384
#: Points whose table search runs at once: its temporaries are
#: [n, V, R, 3] in the fit's precision, 0.8 GB each for 41k points x 25
#: views x 32 roughness cells at once.
TABLE_SEARCH_ROWS = 4096


def _row_chunks(num: int, size: int):
    """Slices of ``range(num)`` of at most ``size``."""
    return [slice(start, min(start + size, num))
            for start in range(0, max(num, 1), size)]


def _one_lighting_captures(data: Data, lightings):
    """Per lighting: its views (V_l,) and the capture of those views
    alone, with its map as ``envmap`` (the photographs left out: the
    observations are projected already)."""
    from tg_intrinsic.transforms.select_views import keep_views
    envmaps, view_lighting = lightings
    base = data.clone()
    for key in ('images', 'envmaps', 'view_lighting'):
        if key in base:
            del base[key]
    captures = []
    for lighting in view_lighting.unique().tolist():
        views = (view_lighting == lighting).nonzero().flatten()
        part = keep_views(base, views)
        part.envmap = envmaps[lighting]
        captures.append((views, part))
    return captures


def _lowest_entropy_start(data: Data, parts) -> Data:
    """``data`` with what the spherical-harmonic steps compute per point
    taken from the lighting of lowest entropy at each point, and the
    mirror directions of every view from its own lighting's part."""
    joint = data.clone()
    first = parts[0][1]
    num = data.num_nodes
    entropy = torch.stack([part.entropy for _, part in parts])   # (L, N)
    choice = entropy.argmin(0)
    points = torch.arange(num, device=choice.device)
    for key in first.keys():
        if key in data or key in ('view_index', 'envmap'):
            continue
        if key == 'mirror_dir':
            mirror = first.mirror_dir.new_zeros(
                (num, data.obs_mask.size(1), 3))
            for views, part in parts:
                mirror[:, views.to(mirror.device)] = part.mirror_dir
            joint.mirror_dir = mirror
        elif torch.is_tensor(first[key]) and first[key].dim() > 0 \
                and first[key].size(0) == num:
            joint[key] = torch.stack([part[key] for _, part in parts])[
                choice, points]
        else:  # the settings of the fits (prefilter, regulariser)
            joint[key] = first[key]
    return joint


def _lit_tables(data: Data, envmap: Optional[Tensor], lightings,
                grid: Tensor, visible: Optional[Tensor], light_samples: int,
                brdf_samples: int, seed: int):
    """:func:`reflection_tables` of the observations in their slots, in
    single precision (Monte Carlo estimates of about 1% noise: float32
    halves their cost), under ``envmap``, or under each view's own map of
    ``lightings`` ``(envmaps, view_lighting)``: then the irradiance is per
    slot, (N, K, 3), each from its view's map."""
    single = torch.float32
    normal, view = data.normal.to(single), data.obs_dir.to(single)
    mask = data.obs_mask.bool()
    if lightings is None:
        return reflection_tables(normal, view, mask, envmap.to(single), grid,
                                 visible, light_samples, brdf_samples, seed)
    envmaps, view_lighting = lightings
    slot_lighting = view_lighting.to(data.obs_view.device)[data.obs_view]
    irradiance = normal.new_zeros(mask.shape + (3, ))
    tables = None
    for lighting in slot_lighting[mask].unique().tolist():
        lit = mask & (slot_lighting == lighting)
        point_irradiance, lit_tables = reflection_tables(
            normal, view, lit, envmaps[lighting].to(single), grid, visible,
            light_samples, brdf_samples, seed)
        irradiance = torch.where(lit.unsqueeze(-1),
                                 point_irradiance.unsqueeze(1), irradiance)
        # zero off the mask: the lightings' tables add up
        tables = lit_tables if tables is None else tables.add_(lit_tables)
    return irradiance, tables


class _IntegralProblem(_Problem):
    """The fitting problem of :meth:`FrequencySVBRDF.refine`: the full
    integral, tabulated over a roughness grid and interpolated linearly
    (the tables do not change with the parameters: nothing to refresh)."""
    def __init__(self, model, data, tv_weight, tv_k, grid: Tensor,
                 irradiance: Tensor, tables: Tensor):
        super().__init__(model, data, tv_weight, tv_k)
        self.grid, self.tables = grid, tables
        # (N, 1, 3) under one lighting, (N, K, 3) under one per view
        self.diffuse = (irradiance if irradiance.dim() == 3
                        else irradiance.unsqueeze(1)) / math.pi

    def refresh(self):
        pass

    def table_search(self):
        """Per point, the best pure dielectric or pure metal over the
        roughness cells of the tables, each with its least-squares base
        colour (clamped to [0, 1]) and scored by the data loss: base colour
        (N, 3), metallic (N), roughness (N)."""
        found = [self._table_search(rows) for rows in _row_chunks(
            self.tables.size(0), TABLE_SEARCH_ROWS)]
        return tuple(torch.cat(column) for column in zip(*found))

    def _table_search(self, rows: slice):
        """:meth:`table_search` of the points in ``rows``."""
        tables = self.tables[rows].to(self.dtype)
        specular = tables[:, :, :, 0]             # [n, V, R, 3]
        constant = tables[:, :, :, 1]
        target = self.target[rows].unsqueeze(2)   # [n, V, 1, 3]
        weight = self.weight[rows].unsqueeze(2)   # [n, V, 1, 1]
        diffuse = self.diffuse[rows].unsqueeze(2)   # [n, 1 or V, 1, 3]
        best_loss = best = None
        for metallic in (0.0, 1.0):
            # prediction = colour * slope + offset, linear in the colour
            slope = specular if metallic else diffuse.expand_as(specular)
            offset = constant + (0.0 if metallic else 0.04 * specular)
            colour = ((weight * slope * (target - offset)).sum(1)
                      / (weight * slope * slope).sum(1).clamp_min(1e-30)
                      ).clamp(0, 1)               # [n, R, 3]
            loss = (weight * (colour.unsqueeze(1) * slope + offset
                              - target).abs()).sum((1, 3))   # [n, R]
            loss, cell = loss.min(1)
            found = (colour[torch.arange(cell.numel(), device=cell.device),
                            cell],
                     torch.full_like(loss, metallic), self.grid[cell])
            if best is None:
                best_loss, best = loss, found
            else:
                take = loss < best_loss
                best = tuple(torch.where(
                    take.view(-1, *[1] * (b.dim() - 1)), f, b)
                    for f, b in zip(found, best))
                best_loss = torch.minimum(loss, best_loss)
        return best

    def predict(self, base_color, metallic, roughness, rows=None,
                jacobian: bool = False):
        rows = torch.arange(self.tables.size(0), device=self.tables.device
                            ) if rows is None else rows
        dtype = self.dtype
        b, m = base_color.to(dtype), metallic.to(dtype).unsqueeze(-1)
        spacing = float(self.grid[1] - self.grid[0])
        t = ((roughness.to(dtype) - self.grid[0]) / spacing).clamp(
            0, self.grid.numel() - 1)
        cell = t.detach().floor().long().clamp(max=self.grid.numel() - 2)
        frac = (t - cell).view(-1, 1, 1)
        lower = self.tables[rows, :, cell].to(dtype)  # [n, V, 2, 3]
        upper = self.tables[rows, :, cell + 1].to(dtype)
        table = lower + (upper - lower) * frac.unsqueeze(-1)
        specular, constant = table[:, :, 0], table[:, :, 1]
        diffuse = self.diffuse[rows]                   # [n, 1 or V, 3]
        r0 = 0.04 * (1 - m) + b * m
        pred = ((b * (1 - m)).unsqueeze(1) * diffuse
                + r0.unsqueeze(1) * specular + constant)
        if not jacobian:
            return pred
        inside = ((roughness > self.grid[0]) & (roughness < self.grid[-1])
                  ).to(dtype).view(-1, 1, 1)
        slope = (upper - lower) / spacing * inside.unsqueeze(-1)
        d_base = ((1 - m).unsqueeze(1) * diffuse + m.unsqueeze(1) * specular)
        d_metallic = -b.unsqueeze(1) * diffuse + (b - 0.04).unsqueeze(
            1) * specular
        d_rough = r0.unsqueeze(1) * slope[:, :, 0] + slope[:, :, 1]
        eye = torch.eye(3, dtype=dtype, device=pred.device)
        jac = torch.cat([d_base.unsqueeze(-1) * eye, d_metallic.unsqueeze(-1),
                         d_rough.unsqueeze(-1)], -1)   # [n, V, 3, 5]
        return pred, jac
