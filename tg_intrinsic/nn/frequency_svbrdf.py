import math
import time
from typing import Optional

import torch
from torch import Tensor
from torch.nn import Parameter
from torch_geometric.data import Data

from tg_intrinsic.geometry import knn, mesh_edges
from tg_intrinsic.geometry.appearance.brdf import (
    MIN_ALPHA, dominant_direction, lobe_degree_sums, model_alpha,
    principled_reflectance, principled_reflectance_jacobian, sh_reflectance)
from tg_intrinsic.geometry.appearance.sh import (fit_light,
                                                 light_directions, real_sh,
                                                 smith_g1)
from tg_intrinsic.geometry.checks import (check_choice, check_image_size,
                                           check_index, check_positive_float,
                                           check_positive_int)
from tg_intrinsic.geometry.texture import texture_grid_edges
from tg_intrinsic.nn.svbrdf_result import SVBRDFResult
from tg_intrinsic.solvers.levenberg_marquardt import levenberg_marquardt

SOLVERS = ('adam', 'lm')
#: Adam steps, or Levenberg-Marquardt iterations per round, by default.
DEFAULT_STEPS = {'adam': 200, 'lm': 20}
# Longest Levenberg-Marquardt step of one parameter: the per-point
# objective has a second minimum at a rough dielectric for rough metals
# (and vice versa) that unbounded first steps jump into; measured on the
# model's own observations, 0.05 recovers every point, 0.1 loses 3%.
MAX_STEP = 0.05
_NEEDED = ('sh_in', 'light_radiance', 'mirror_dir', 'irradiance',
           'obs_radiance', 'obs_mask', 'sh_prefilter')


class FrequencySVBRDF(torch.nn.Module):
    r"""Per-point principled SVBRDF parameters with the differentiable
    spherical-harmonic reflection model of Wiersma et al., "Uncertainty for
    SVBRDF Acquisition using Frequency Analysis" (SIGGRAPH 2025, eq. 5.11),

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
        """Predicted radiance at every observation :math:`(N, V, 3)`.
        ``sh_in`` (default ``data.sh_in``) and ``basis`` (harmonics at the
        mirror directions) may be passed precomputed."""
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
          iteratively reweighted least squares for the L1 distance. The
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
                with
                :obj:`'lm'`, every round pulls each point towards its
                neighbours' values of the previous round. (default:
                :obj:`0.0`)
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
        if metallic is not None and not (isinstance(metallic, (int, float))
                                         and 0 <= metallic <= 1):
            raise ValueError(f"'metallic' must be None (fitted) or a number "
                             f"in [0, 1], got {metallic!r}")
        self._check(data)
        texture_shape, texel_index = self._texels(data)
        observed = data.obs_radiance[data.obs_mask.bool()]
        if not bool(torch.isfinite(observed).all()):
            raise ValueError("'data.obs_radiance' holds NaN or infinite "
                             "radiance at observed entries; mask them out "
                             "in 'obs_mask' (ProjectViews does so for NaN "
                             "pixels)")
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
        with torch.no_grad():
            final = float(problem.loss(self.base_color, self.metallic,
                                       self.roughness))
        return SVBRDFResult(
            base_color=self.base_color.detach().clone(),
            metallic=self.metallic.detach().clone(),
            roughness=self.roughness.detach().clone(),
            entropy=getattr(data, 'entropy', None),
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
            residual, jacobian = problem.residual(x0, columns)
            x, _ = levenberg_marquardt(
                residual, x0, problem.point_weight(len(columns)),
                lower.to(x0), torch.ones_like(lower).to(x0), loss='l1',
                max_iter=steps, tol=1e-4,
                l1_epsilon=1e-3 * problem.radiance_scale, jacobian=jacobian,
                max_step=MAX_STEP)
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
        self.tv_weight = tv_weight
        self.edges = model._graph(data, tv_k) if tv_weight > 0 \
            else None
        self.neighbours = None if self.edges is None \
            else _neighbour_table(self.edges, data.sh_in.size(0))
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
        error = self.predict(base_color, metallic, roughness) - self.target
        return (self.weight * error.abs()).sum() / self.normaliser

    def objective(self) -> Tensor:
        """The model's data loss plus its total variation, if any."""
        model = self.model
        loss = self.loss(model.base_color, model.metallic, model.roughness)
        if self.edges is not None:
            loss = loss + self.tv_weight * model.total_variation(self.edges)
        return loss

    def point_weight(self, num_params: int) -> Tensor:
        """Weights of the residuals of :meth:`residual`, per point: the
        observations', then the total variation's (each edge pulls on both
        of its points, so twice the weight of one term of the mean)."""
        w = self.weight.expand_as(self.target).reshape(self.target.size(0),
                                                       -1)
        w = w / self.normaliser
        if self.neighbours is None:
            return w
        tv = (self.neighbours >= 0).to(w) * (
            2 * self.tv_weight / self.edges.size(1))
        tv = tv.repeat_interleave(num_params, 1)
        return torch.cat([w, tv], 1)

    def residual(self, current: Tensor, columns):
        """The residuals of the points ``rows`` at parameters ``x``, the
        ``columns`` of (base colour, metallic, roughness) that are fitted,
        and a function that also returns their Jacobian. ``current`` holds
        every point's values of the previous round, which the total
        variation pulls towards (block Jacobi)."""
        metallic = self.model.metallic.detach().to(self.dtype)
        fixed_metallic = 3 not in columns

        def arguments(x, rows):
            m = metallic[rows] if fixed_metallic else x[:, 3]
            return x[:, :3], m, x[:, -1], rows

        def variation(x, rows):
            table = self.neighbours[rows]
            other = current[table.clamp_min(0)]
            diff = torch.where((table >= 0).unsqueeze(-1),
                               x.unsqueeze(1) - other, 0 * other)
            return diff.reshape(rows.numel(), -1)

        def residual(x, rows):
            pred = self.predict(*arguments(x, rows))
            out = (pred - self.target[rows]).reshape(rows.numel(), -1)
            if self.neighbours is None:
                return out
            return torch.cat([out, variation(x, rows)], 1)

        def jacobian(x, rows):
            pred, jac = self.predict(*arguments(x, rows), jacobian=True)
            n, p = rows.numel(), len(columns)
            out = (pred - self.target[rows]).reshape(n, -1)
            jac = jac[..., columns].reshape(n, -1, p)
            if self.neighbours is None:
                return out, jac
            eye = torch.eye(p, dtype=jac.dtype, device=jac.device)
            tv_jac = eye.repeat(self.neighbours.size(1), 1).expand(n, -1, -1)
            return (torch.cat([out, variation(x, rows)], 1),
                    torch.cat([jac, tv_jac], 1))
        return residual, jacobian


def _neighbour_table(edges: Tensor, num: int) -> Tensor:
    """The neighbours ``edges[0]`` of every centre ``edges[1]`` as rows of
    a ``[N, D]`` table padded with -1."""
    nbr, centre = edges
    order = torch.argsort(centre, stable=True)
    nbr, centre = nbr[order], centre[order]
    counts = torch.bincount(centre, minlength=num)
    start = torch.cumsum(counts, 0) - counts
    slot = torch.arange(centre.numel(), device=centre.device) - start[centre]
    table = torch.full((num, max(int(counts.max()), 1)), -1,
                       dtype=torch.long, device=centre.device)
    table[centre, slot] = nbr
    return table
