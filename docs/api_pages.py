"""The API reference's pages: each lists the public names (``__all__``) of
its modules, in this order, a name shown once (re-exports under the first
module that lists them; a module whose names are all shown already gets no
section). ``conf.py`` writes the pages from this at every
build; ``tests/test_docs.py`` checks that every module with an ``__all__``
is here."""

#: page title -> modules
API_PAGES = {
    'tg_intrinsic': ['tg_intrinsic', 'tg_intrinsic.surface_attributes',
                     'tg_intrinsic.errors'],
    'geometry': ['tg_intrinsic.geometry', 'tg_intrinsic.geometry.texture',
                 'tg_intrinsic.geometry.precision', 'tg_intrinsic.geometry.jit',
                 'tg_intrinsic.geometry.sphere_images',
                 'tg_intrinsic.geometry.pointcloud',
                 'tg_intrinsic.geometry.pointcloud.neighbors',
                 'tg_intrinsic.geometry.pointcloud.diffusion',
                 'tg_intrinsic.geometry.geodesics',
                 'tg_intrinsic.geometry.geodesics.logmap',
                 'tg_intrinsic.geometry.geodesics.harmonic',
                 'tg_intrinsic.geometry.geodesics.affine_heat',
                 'tg_intrinsic.geometry.multigrid',
                 'tg_intrinsic.geometry.appearance',
                 'tg_intrinsic.geometry.appearance.cameras',
                 'tg_intrinsic.geometry.appearance.raster',
                 'tg_intrinsic.geometry.appearance.lighting',
                 'tg_intrinsic.geometry.appearance.direct_lighting',
                 'tg_intrinsic.geometry.appearance.dynamic_range',
                 'tg_intrinsic.geometry.appearance.splat',
                 'tg_intrinsic.geometry.appearance.distortion',
                 'tg_intrinsic.geometry.appearance.observations',
                 'tg_intrinsic.geometry.appearance.photograph_stack'],
    'transforms': ['tg_intrinsic.transforms'],
    'nn': ['tg_intrinsic.nn', 'tg_intrinsic.nn.harmonic_resnet_block'],
    'nn.models': ['tg_intrinsic.nn.models'],
    'pool': ['tg_intrinsic.pool'],
    'solvers': ['tg_intrinsic.solvers'],
    'datasets': ['tg_intrinsic.datasets', 'tg_intrinsic.datasets.capture'],
    'io': ['tg_intrinsic.io', 'tg_intrinsic.io.scene', 'tg_intrinsic.io.gltf',
           'tg_intrinsic.io.capture', 'tg_intrinsic.io.capture_files',
           'tg_intrinsic.io.capture_views', 'tg_intrinsic.io.capture_writer',
           'tg_intrinsic.io.colmap', 'tg_intrinsic.io.transforms_json',
           'tg_intrinsic.io.stanford_orb', 'tg_intrinsic.io.photographs'],
    'train and protocols': ['tg_intrinsic.train', 'tg_intrinsic.training',
                            'tg_intrinsic.protocols',
                            'tg_intrinsic.devices',
                            'tg_intrinsic.distributed'],
}
