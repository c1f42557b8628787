import re
import runpy

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

# the extras and what needs each are listed once, in tg_intrinsic/extras.py
# (run, not imported: importing the package needs torch)
extras_require = {
    name: requirements for name, (requirements, _) in
    runpy.run_path('tg_intrinsic/extras.py')['EXTRAS'].items()}

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
