"""The optional extras, ``pip install "tg_intrinsic[NAME]"``: what each
installs and what needs it. ``setup.py`` reads this file (running it, not
importing the package, which needs torch) and ``tg-intrinsic info`` shows
it, so the two cannot disagree. Plain data, no imports."""

#: Every extra: its requirements and what needs it.
EXTRAS = {
    'heat': (['potpourri3d>=1.0'],
             "log maps with method='vector_heat' (geometry-central's "
             "vector heat method)"),
    'exr': (['OpenEXR>=3.2'],
            'reading and writing .exr photographs and environment maps '
            '(Radiance .hdr needs nothing extra)'),
    'textures': (['xatlas>=0.0.9'],
                 'UV atlases for meshes without UVs (svbrdf --texture, '
                 'uv_atlas)'),
    'h5': (['h5py>=3.8'], "ScanObjectNN's HDF5 files"),
    'digits': (['scikit-learn>=1.2'],
               "SphereDigits (scikit-learn's bundled 8x8 digits)"),
    'scatter': (['torch-scatter'],
                'compiled scatter kernels; the results do not change'),
    'mitsuba': (['mitsuba>=3.5'],
                'the external renderer of the SVBRDF oracle test and '
                'benchmark (its llvm variant also needs libllvm19)'),
    'benchmarks': (['cholespy>=2.0'],
                   'the direct-solver peer (CHOLMOD) of '
                   'benchmarks/gravo_applications.py'),
    'docs': (['sphinx>=7.0', 'furo>=2024.1', 'myst-parser>=3.0',
              'sphinx-gallery>=0.17', 'sphinx-mathjax-offline>=0.0.2'],
             'the documentation site (make docs)'),
    'test': ([
        'pytest>=7',
        'hypothesis>=6.80',
        'robust-laplacian>=0.2.7',
        'potpourri3d>=1.0',
        # independent oracles of the HDR readers (tests/io)
        'opencv-python-headless>=4.8',
        'OpenEXR>=3.2',
        'h5py>=3.8',
        'scikit-learn>=1.2',
        # svbrdf --texture, and a glTF reader that is not ours
        'xatlas>=0.0.9',
        'pygltflib>=1.16',
        # a reader of COLMAP models that is not ours (tests/io/test_colmap.py)
        'pycolmap>=3.10',
        # the wheel as users get it (tests/test_packaging.py; built without
        # isolation, so with this environment's setuptools)
        'build>=1.0',
        'setuptools>=70.1',
        'twine>=5.0',
        # docstrings of constants (tests/test_docs.py)
        'sphinx>=7.0',
    ], 'the test suite (make test)'),
}
