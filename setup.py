import re

from setuptools import find_packages, setup

# the version is defined once, in tg_intrinsic/__init__.py (read, not
# imported: importing needs torch, which the build must not)
with open('tg_intrinsic/__init__.py', encoding='utf-8') as f:
    VERSION = re.search(r"^__version__ = '([^']+)'$", f.read(), re.M).group(1)

# torch is listed without a pin so that users keep the build (CPU or CUDA) they
# installed first; the Makefile installs the CPU build torch==2.13.0 before this.
install_requires = [
    'torch>=2.4',
    'torch-geometric>=2.8,<2.9',
    'numpy>=1.24',
    'scipy>=1.10',
    'trimesh>=4.0',
    'numba>=0.59',
    'pyamg>=5.0',
    'robust-laplacian>=0.2.7',
    'tqdm>=4.60',
    'matplotlib>=3.7',
    'fast-simplification>=0.2',  # Decimate (preserve_border from 0.2)
]

extras_require = {
    'test': [
        'pytest>=7',
        'hypothesis>=6.80',
        'robust-laplacian>=0.2.7',
        'potpourri3d>=1.0',
        # independent oracles of the HDR readers (tests/io)
        'opencv-python-headless>=4.8',
        'OpenEXR>=3.2',
        # ScanObjectNN's HDF5 files (tests/datasets)
        'h5py>=3.8',
        # SphereDigits' 8x8 digits (bundled in the wheel, no download)
        'scikit-learn>=1.2',
        # svbrdf --texture: a UV atlas, and a glTF reader that is not ours
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
    ],
    # The documentation site: make docs.
    'docs': ['sphinx>=7.0', 'furo>=2024.1', 'myst-parser>=3.0',
             'sphinx-gallery>=0.17'],
    # log_map(method='vector_heat'): geometry-central's vector heat method.
    'heat': ['potpourri3d>=1.0'],
    # Optional compiled scatter kernels; results must not change with it.
    'scatter': ['torch-scatter'],
    # read_exr; Radiance .hdr needs nothing extra.
    'exr': ['OpenEXR>=3.2'],
    # ScanObjectNN's HDF5 files.
    'h5': ['h5py>=3.8'],
    # The direct-solver peer (CHOLMOD) of benchmarks/gravo_applications.py.
    'benchmarks': ['cholespy>=2.0'],
    # The external renderer of the SVBRDF oracle test and benchmark
    # (its llvm variant also needs: apt-get install libllvm19).
    'mitsuba': ['mitsuba>=3.5'],
    # SphereDigits: scikit-learn's bundled 8x8 digits.
    'digits': ['scikit-learn>=1.2'],
    # UV atlases for meshes without UVs (svbrdf --texture, uv_atlas).
    'textures': ['xatlas>=0.0.9'],
}

setup(
    name='tg_intrinsic',
    version=VERSION,
    description=('PyTorch Geometric extension for learning and computing on '
                 'curved surfaces with intrinsic geometry'),
    long_description=open('README.md', encoding='utf-8').read(),
    long_description_content_type='text/markdown',
    # torch 2.13.0, pinned, declares Requires-Python >=3.10
    python_requires='>=3.10',
    packages=find_packages(include=['tg_intrinsic', 'tg_intrinsic.*']),
    install_requires=install_requires,
    extras_require=extras_require,
    entry_points={
        'console_scripts': ['tg-intrinsic = tg_intrinsic.cli:entry_point'],
    },
    license='MIT',
)
