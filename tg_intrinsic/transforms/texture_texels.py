from typing import Sequence, Tuple

from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry import vertex_normals, weld_vertices
from tg_intrinsic.geometry.checks import (check_faces, check_image_size,
                                          check_points, check_unit_interval)
from tg_intrinsic.geometry.texture import rasterize_uv
from tg_intrinsic.surface_attributes import given_normals
from tg_intrinsic.transforms._batching import GraphTransform
from tg_intrinsic.transforms._mesh_ops import split_attributes

# The capture: per view or global, never per vertex or per face, whatever
# their first dimension happens to be.
CAPTURE_KEYS = ('images', 'intrinsics', 'extrinsics', 'envmap')
# The mesh and its UVs and normals: replaced by their texel counterparts.
MESH_KEYS = ('pos', 'face', 'uv', 'face_uv', 'normal', 'norm', 'frame')


@functional_transform('texture_texels')
class TextureTexels(GraphTransform):
    r"""Turns a UV-mapped triangle mesh into the covered texels of an
    :math:`(H, W)` texture (functional name: :obj:`texture_texels`), so
    that frequency-domain SVBRDF recovery (Wiersma et al., SIGGRAPH 2025)
    works in UV space, as the paper does, and exports texture images.

    Each texel whose centre :math:`(u_c, v_r)` falls inside a UV triangle
    :math:`f` becomes a point at the barycentric interpolation of the
    triangle's corners (:func:`~tg_intrinsic.geometry.texture.rasterize_uv`),

    .. math::
        (u_c, v_r) = \sum_k \lambda_k\, (u, v)_{f,k}, \qquad
        p = \sum_k \lambda_k\, p_{f,k}, \qquad
        n = \frac{\sum_k \lambda_k\, n_{f,k}}{\|\sum_k \lambda_k\,
        n_{f,k}\|},

    with texel centres :math:`u_c = (c + \frac12) / W`, :math:`v_r = 1 -
    (r + \frac12) / H`: row 0 of the texture is its top, :math:`v = 1`
    (the OBJ / OpenGL convention for images stored top row first). A
    texel covered by several triangles (a shared edge, overlapping
    charts) takes the one of lowest index. The vertex normals
    :math:`n_i` are the data's (``normal``, ``norm`` or ``frame``), else
    area-weighted vertex normals of the mesh with its UV seams welded
    (vertices at the same position merged), so normals do not crease
    where the UV layout cut the surface.

    The output goes straight into
    :class:`~tg_intrinsic.transforms.ProjectViews` (which needs points,
    normals and the capture, not the mesh),
    :class:`~tg_intrinsic.transforms.FitSphericalHarmonics`,
    :class:`~tg_intrinsic.transforms.SpectralUncertainty` and
    :meth:`~tg_intrinsic.nn.FrequencySVBRDF.fit`, which then regularises
    along the texture grid and exports texture images. Attributes:
    the capture (``images``, ``intrinsics``, ``extrinsics``, ``envmap``)
    and every other attribute that is neither per vertex (first dimension
    :math:`V`) nor per triangle (first dimension :math:`F \neq V`) are
    kept; per-vertex tensors named in :obj:`interpolate` are interpolated
    like :math:`p` (e.g. a ground-truth material), other per-vertex ones
    (observations per vertex, ``x``, ...) are dropped; per-triangle
    tensors take the value of the texel's triangle. ``texel_index``
    indexes the texture, not the points, so batching such data with PyG
    (which offsets ``*_index`` keys by the point count) is not supported,
    and the transform refuses a collated
    :class:`~torch_geometric.data.Batch`.

    Args:
        texture_shape (tuple): ``(H, W)``, the texture's rows and columns.
        interpolate (sequence of str, optional): Per-vertex float
            attributes to interpolate onto the texels. (default: :obj:`()`)
        keep_mesh (bool, optional): Keep the mesh as ``mesh_pos`` and
            ``mesh_face`` (``texel_face`` indexes its triangles); under
            these names no transform or model takes it for the points'
            mesh. (default: :obj:`True`)

    Shapes:
        - **input:** ``pos`` :math:`(V, 3)`, ``face`` :math:`(3, F)`, and
          UVs in :math:`[0, 1]^2`, either per vertex, ``uv``
          :math:`(V, 2)`, or per triangle corner, ``face_uv``
          :math:`(3, F, 2)` (``face_uv[k, f]`` the UV of corner ``face[k,
          f]``, as OBJ ``vt`` indices give them; it wins if both are
          given); optionally ``normal`` :math:`(V, 3)`
        - **output:** ``pos`` :math:`(N, 3)`, ``normal`` :math:`(N, 3)`,
          ``texel_index`` :math:`(N)` (flat row-major :math:`rW + c`,
          increasing), ``texel_face`` :math:`(N)`, ``texel_bary``
          :math:`(N, 3)`, ``texture_shape`` ``(H, W)``, :math:`N \leq HW`
    """
    batch_refusal = ("its texel_index numbers texels of a texture and "
                     "mesh_face the triangles of the kept mesh, which PyG's "
                     "collation would offset and concatenate wrongly")

    def __init__(self, texture_shape: Tuple[int, int],
                 interpolate: Sequence[str] = (), keep_mesh: bool = True):
        self.texture_shape = check_image_size(texture_shape, 'texture_shape')
        if isinstance(interpolate, str) or not all(
                isinstance(key, str) for key in interpolate):
            raise ValueError(f"'interpolate' must be a sequence of attribute "
                             f"names, got {interpolate!r}")
        self.interpolate = tuple(interpolate)
        self.keep_mesh = bool(keep_mesh)

    def forward(self, data: Data) -> Data:
        pos, face = getattr(data, 'pos', None), getattr(data, 'face', None)
        if pos is None or face is None:
            raise ValueError("TextureTexels needs a UV-mapped mesh: "
                             "'data.pos' [V, 3] and 'data.face' [3, F]")
        pos = check_points(pos, 'pos')
        face = check_faces(face, pos.size(0), pos)
        face_uv = self._face_uv(data, pos, face)
        height, width = self.texture_shape
        texel_index, texel_face, bary = rasterize_uv(face_uv, height, width)
        if texel_index.numel() == 0:
            raise ValueError(f"no texel centre of the {height} x {width} "
                             f"texture falls inside a UV triangle (the UV "
                             f"triangles are smaller than a texel, or of "
                             f"zero area); use a larger texture_shape")
        bary = bary.to(pos)
        corners = face[:, texel_face]  # (3, N)

        def interpolated(value):
            return (bary.t().reshape((3, -1) + (1, ) * (value.dim() - 1))
                    * value[corners]).sum(0)

        normal = interpolated(self._vertex_normals(data, pos, face))
        normal = normal / normal.norm(dim=-1, keepdim=True).clamp_min(1e-30)
        vertex_keys, face_keys = split_attributes(data, pos.size(0),
                                                  face.size(1))
        for key in self.interpolate:
            if key not in vertex_keys or key in MESH_KEYS:
                raise ValueError(f"'interpolate' names {key!r}, which is not "
                                 f"a per-vertex attribute of the data (first "
                                 f"dimension {pos.size(0)}) other than the "
                                 f"mesh, UVs and normals")
            if not data[key].is_floating_point():
                raise ValueError(f"'data.{key}' is {data[key].dtype}; only "
                                 f"float attributes can be interpolated")

        out = {}
        for key, value in data.items():
            if key in CAPTURE_KEYS or (key not in MESH_KEYS
                                       and key not in vertex_keys
                                       and key not in face_keys):
                out[key] = value
            elif key in face_keys and key not in MESH_KEYS:
                out[key] = value[texel_face.to(value.device)]
            elif key in self.interpolate:
                out[key] = interpolated(value.to(pos.device)).to(value)
        out.update(pos=interpolated(pos), normal=normal,
                   texel_index=texel_index.to(pos.device),
                   texel_face=texel_face.to(pos.device),
                   texel_bary=bary, texture_shape=(height, width))
        if self.keep_mesh:
            out.update(mesh_pos=pos, mesh_face=face)
        return data.__class__(**out)

    @staticmethod
    def _face_uv(data: Data, pos, face):
        """The UVs of every triangle corner, ``[3, F, 2]``, checked."""
        face_uv = getattr(data, 'face_uv', None)
        if face_uv is not None:
            return check_unit_interval(face_uv, 'face_uv',
                                       (3, face.size(1), 2)).to(pos.device)
        uv = getattr(data, 'uv', None)
        if uv is None:
            raise ValueError("TextureTexels needs UVs: 'data.uv' [V, 2] per "
                             "vertex or 'data.face_uv' [3, F, 2] per "
                             "triangle corner, in [0, 1]^2")
        uv = check_unit_interval(uv, 'uv', (pos.size(0), 2))
        return uv[face.cpu()].to(pos.device)

    @staticmethod
    def _vertex_normals(data: Data, pos, face):
        given = given_normals(data)
        if given is not None:
            return given.to(pos)
        # UV seams duplicate vertices; their normals must see both sides.
        welded, welded_face, inverse = weld_vertices(pos, face)
        return vertex_normals(welded, welded_face)[inverse]

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}(texture_shape='
                f'{self.texture_shape}, interpolate={list(self.interpolate)}'
                f', keep_mesh={self.keep_mesh})')

