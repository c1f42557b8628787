"""Sphinx configuration of the documentation site.

Nothing here is written by hand twice: the API reference is generated
from every module's ``__all__`` (``api_pages.py``), the pages include the
sections of ``README.md`` that hold their text, the results table is the
README's (written by ``benchmarks/report.py`` from
``benchmarks/results/*.json``), and the examples in ``examples/`` become a
gallery, run with ``--quick`` when the site is built. The build reads no
network: torch, PyG, numpy and scipy names link to their sites by URL.

    make docs        # -> docs/_build/html, warnings are errors
"""
import importlib
import inspect
import os
import sys

from docutils import nodes

DOCS = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(DOCS)
sys.path.insert(0, ROOT)
sys.path.insert(0, DOCS)

import tg_intrinsic  # noqa: E402
from api_pages import API_PAGES  # noqa: E402

project = 'tg_intrinsic'
author = 'tg_intrinsic contributors'
copyright = '2026, tg_intrinsic contributors'
release = version = tg_intrinsic.__version__

extensions = [
    'sphinx.ext.autodoc',
    'sphinx.ext.autosummary',
    'sphinx.ext.napoleon',
    'sphinx.ext.mathjax',
    'sphinx.ext.viewcode',
    'myst_parser',
    'sphinx_gallery.gen_gallery',
]
source_suffix = {'.rst': 'restructuredtext', '.md': 'markdown'}
exclude_patterns = ['_build', 'auto_examples/*.ipynb', 'auto_examples/*.py',
                    'auto_examples/*.zip', 'auto_examples/*.json',
                    'auto_examples/*.md5', 'sg_execution_times.rst',
                    'auto_examples/sg_execution_times.rst']
html_theme = 'furo'
html_title = f'tg_intrinsic {release}'
myst_heading_anchors = 3
myst_enable_extensions = ['dollarmath']

autosummary_generate = True
autodoc_default_options = {'members': True, 'show-inheritance': True}
autodoc_member_order = 'bysource'
autodoc_typehints = 'signature'
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_custom_sections = ['Shapes']

# -- the gallery: examples/ run with --quick (gallery.py), figures collected -
sphinx_gallery_conf = {
    'examples_dirs': os.path.join(ROOT, 'examples'),
    'gallery_dirs': 'auto_examples',
    'filename_pattern': r'.*\.py$',
    'reset_argv': 'gallery.example_arguments',
    'download_all_examples': False,
    'remove_config_comments': True,
    'within_subsection_order': 'FileNameSortKey',
    'show_memory': False,
    'show_signature': False,
}

# -- links to the libraries this one builds on, by URL ----------------------
EXTERNAL = (
    ('torch_geometric.', 'https://pytorch-geometric.readthedocs.io/en/latest/'
                         'generated/{}.html'),
    ('torch.Tensor', 'https://docs.pytorch.org/docs/stable/tensors.html'),
    ('torch.', 'https://docs.pytorch.org/docs/stable/generated/{}.html'),
    ('numpy.', 'https://numpy.org/doc/stable/reference/generated/{}.html'),
    ('scipy.', 'https://docs.scipy.org/doc/scipy/reference/generated/'
               '{}.html'),
)


def public_path(target: str) -> str:
    """``target`` under the shortest module that exports it: type hints
    name classes where they are defined (``torch_geometric.data.data.Data``),
    the libraries' sites under their public path
    (``torch_geometric.data.Data``)."""
    parts = target.split('.')
    for end in range(1, len(parts) - 1):
        try:
            module = importlib.import_module('.'.join(parts[:end]))
        except ImportError:
            continue
        if hasattr(module, parts[-1]):
            return '.'.join(parts[:end] + parts[-1:])
    return target


def link_external(app, env, node, contnode):
    """A reference to a torch, PyG, numpy or scipy name becomes a link to
    its page on the library's site (no inventory is fetched)."""
    target = public_path(node.get('reftarget', ''))
    for prefix, url in EXTERNAL:
        if target == prefix.rstrip('.') or target.startswith(prefix):
            reference = nodes.reference('', '', internal=False,
                                        refuri=url.format(target))
            reference += contnode
            return reference
    return None


# -- the API reference, one page per entry of API_PAGES ---------------------
def write_api_pages():
    """``api/<page>.rst`` with an autosummary table per module, each name
    under the first module of the page that lists it."""
    folder = os.path.join(DOCS, 'api', 'pages')
    os.makedirs(folder, exist_ok=True)
    for title, modules in API_PAGES.items():
        slug = title.replace(' ', '_').replace('.', '_')
        lines = [title, '=' * len(title), '']
        shown = set()
        for module_name in modules:
            module = importlib.import_module(module_name)
            # sub-packages have pages of their own
            names = [n for n in module.__all__ if n not in shown
                     and not n.startswith('__')
                     and not inspect.ismodule(getattr(module, n))]
            if not names:
                continue
            shown.update(names)
            lines += [f'``{module_name}``', '-' * (len(module_name) + 4), '',
                      f'.. automodule:: {module_name}', '   :no-members:',
                      '', f'.. currentmodule:: {module_name}', '']
            lines += ['.. autosummary::', '   :toctree: generated',
                      '   :nosignatures:', '']
            lines += [f'   {name}' for name in names] + ['']
        text = '\n'.join(lines)
        path = os.path.join(folder, f'{slug}.rst')
        if not os.path.exists(path) or open(path).read() != text:
            with open(path, 'w') as f:
                f.write(text)


write_api_pages()


def setup(app):
    app.connect('missing-reference', link_external)
