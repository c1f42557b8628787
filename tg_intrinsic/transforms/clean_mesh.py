import torch
from torch_geometric.data import Data
from torch_geometric.data.datapipes import functional_transform

from tg_intrinsic.geometry import face_areas, weld_vertices
from tg_intrinsic.transforms._batching import GraphTransform
from tg_intrinsic.transforms._mesh_ops import (DEGENERATE_TOLERANCE,
                                              check_mesh_data, compact,
                                              component_labels,
                                              fan_triangulate,
                                              first_unique_faces,
                                              nondegenerate, rebuild)


@functional_transform('clean_mesh')
class CleanMesh(GraphTransform):
    r"""Makes a raw scanned or exported mesh usable by the surface
    transforms (functional name: :obj:`clean_mesh`). It runs these steps,
    in this order:

    1. polygons (``face`` of shape :math:`(k, F)`, :math:`k > 3`, rows of
       -1 padding shorter ones) become triangle fans
       :math:`(c_0, c_t, c_{t+1})`, as
       :func:`tg_intrinsic.io.mesh.read_mesh` does for files;
    2. vertices with NaN or infinite coordinates are dropped with their
       triangles;
    3. duplicate vertices are welded
       (:func:`~tg_intrinsic.geometry.weld_vertices`, exact or within
       :obj:`weld_tolerance` of the bounding-box diagonal), which connects
       a triangle soup; a welded vertex keeps the attributes of its first
       copy;
    4. degenerate triangles are dropped: repeated corners, or a small
       area against the longest edge (the geometry code rejects them),

       .. math::
           A_f \le \tau \max_{e \in f} \ell_e^2, \qquad
           \tau = 10^{-5};

    5. duplicate triangles (the same three vertices, in either
       orientation) are dropped, keeping the first;
    6. with :obj:`largest_component`, only the connected component of
       largest area is kept; otherwise every component stays (the
       geodesic code handles several: no disc crosses between them);
    7. vertices that no triangle references are dropped.

    Per-vertex tensors (first dimension :math:`N`: ``y``, ``x``,
    ``normal``, ...) follow their vertices, per-face tensors (first
    dimension :math:`F \neq N`) their triangles; other attributes are kept
    as they are. Edges shared by more than two triangles (non-manifold)
    are left: the ``'fast'`` log map works on them, while
    ``method='vector_heat'`` rejects them with a message.

    Args:
        weld_tolerance (float, optional): Weld vertices closer than this
            fraction of the bounding-box diagonal; 0 welds exact
            duplicates only. (default: :obj:`0.0`)
        largest_component (bool, optional): Keep only the component with
            the largest area. (default: :obj:`False`)

    Shapes:
        - **input:** ``pos`` :math:`(N, 3)`, ``face`` :math:`(k, F)`
        - **output:** ``pos`` :math:`(N', 3)`, ``face`` :math:`(3, F')`,
          :math:`N' \le N`
    """
    def __init__(self, weld_tolerance: float = 0.0,
                 largest_component: bool = False):
        if not weld_tolerance >= 0:
            raise ValueError(f"'weld_tolerance' must be a non-negative "
                             f"fraction of the bounding-box diagonal, got "
                             f"{weld_tolerance!r}")
        self.weld_tolerance = float(weld_tolerance)
        self.largest_component = bool(largest_component)

    def forward(self, data: Data) -> Data:
        pos, face = check_mesh_data(data, 'CleanMesh')
        n = pos.size(0)
        face, owner = fan_triangulate(face)
        # Vertices: finite ones, welded; ``keep`` is the input vertex behind
        # every current one.
        finite = torch.isfinite(pos).all(1)
        face_ok = finite[face].all(0) if face.size(1) else \
            torch.zeros(0, dtype=torch.bool)
        face, owner = face[:, face_ok], owner[face_ok]
        keep = finite.nonzero().flatten()
        if keep.numel() == 0:
            raise ValueError("CleanMesh: every vertex has NaN or infinite "
                             "coordinates")
        remap = torch.full((n,), -1, dtype=torch.long, device=pos.device)
        remap[keep] = torch.arange(keep.numel(), device=pos.device)
        face = remap[face]
        welded, face, inverse = weld_vertices(pos[keep], face,
                                              self.weld_tolerance)
        first = torch.full((welded.size(0),), keep.numel(), dtype=torch.long,
                           device=pos.device).scatter_reduce(
            0, inverse, torch.arange(inverse.numel(), device=pos.device),
            reduce='amin')
        keep = keep[first]
        # Triangles: non-degenerate, unique.
        good = nondegenerate(welded, face, DEGENERATE_TOLERANCE)
        face, owner = face[:, good], owner[good]
        unique = first_unique_faces(face, welded.size(0))
        face, owner = face[:, unique], owner[unique]
        if face.size(1) == 0:
            raise ValueError("CleanMesh: no triangle is left (every one is "
                             "degenerate); the input is not a surface mesh"
                             " - for a point cloud drop 'data.face'")
        if self.largest_component:
            label = torch.from_numpy(component_labels(
                face, welded.size(0))).to(face.device)
            area = face_areas(welded, face)
            total = torch.zeros(int(label.max()) + 1, dtype=area.dtype,
                                device=area.device).index_add_(
                0, label[face[0]], area)
            inside = label[face[0]] == int(torch.argmax(total))
            face, owner = face[:, inside], owner[inside]
        face, kept = compact(face, welded.size(0))
        return rebuild(data, welded[kept], face, keep[kept], owner)

    def __repr__(self) -> str:
        return (f'{self.__class__.__name__}('
                f'weld_tolerance={self.weld_tolerance}, '
                f'largest_component={self.largest_component})')
