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
    # MathJax served from the build, not a CDN: maths shows offline
    'sphinx-mathjax-offline',
    'sphinx.ext.viewcode',
    'myst_parser',
    'sphinx_gallery.gen_gallery',
]
source_suffix = {'.rst': 'restructuredtext', '.md': 'markdown'}
exclude_patterns = ['_build', 'results/summary.md',
                    'auto_examples/*.ipynb', 'auto_examples/*.py',
                    'auto_examples/*.zip', 'auto_examples/*.json',
                    'auto_examples/*.md5', 'sg_execution_times.rst',
                    'auto_examples/sg_execution_times.rst']
html_theme = 'furo'
# smart quotes, but '--' stays '--' (as a dash it breaks a pasted command)
smartquotes_action = 'qe'
html_title = f'tg_intrinsic {release}'
myst_heading_anchors = 3
myst_enable_extensions = ['dollarmath']

templates_path = ['_templates']  # class pages: the class's own members only
autosummary_generate = True
autodoc_default_options = {'members': True, 'show-inheritance': True}
autodoc_member_order = 'bysource'
autodoc_typehints = 'signature'
# an override without a docstring (MessagePassing.message, ...) is not shown
# with its parent's text, which describes PyG's method, not this one
autodoc_inherit_docstrings = False
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
#: public name -> the full name its API entry has
DOCUMENTED = {}


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
            DOCUMENTED.update((n, f'{module_name}.{n}') for n in names
                              if n not in DOCUMENTED)
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


# -- the results: a short table and a page per benchmark ---------------------
RESULTS = os.path.join(ROOT, 'benchmarks', 'results')


def headline(result: str, limit: int = 160) -> str:
    """A result's first clause (to its first ';' or sentence end), at most
    ``limit`` characters, cut between words, with no bracket or bold mark
    left open by the cut."""
    import re
    first = re.split(r'; |\. (?=[A-Z])', result, maxsplit=1)[0]
    cut = len(first) > limit
    if cut:
        first = first[:limit].rsplit(' ', 1)[0]
    opened = []
    for index, character in enumerate(first):
        if character == '(':
            opened.append(index)
        elif character == ')' and opened:
            opened.pop()
    if opened:  # cut before the bracket the cut left open
        first, cut = first[:opened[0]].rstrip(' ,:'), True
    if first.count('**') % 2:
        first = first[:first.rindex('**')].rstrip(' ,:')
        cut = True
    return first + (' ...' if cut else '')


def write_results_pages():
    """``results/pages/<benchmark>.md``: the rows of README's results table
    that a benchmark's JSON gives, its figure (read from
    ``benchmarks/results/`` at build time) and how to rerun it; and
    ``results/summary.md``, one line per claim, which the Results page
    includes."""
    sys.path.insert(0, os.path.join(ROOT, 'benchmarks'))
    try:
        from report import table_rows
    finally:
        sys.path.pop(0)
    folder = os.path.join(DOCS, 'results', 'pages')
    os.makedirs(folder, exist_ok=True)
    pages, summary = {}, ['| claim | headline | details |', '|---|---|---|']
    for name, (claim, script, result) in table_rows(RESULTS):
        pages.setdefault(name, (script, []))[1].append((claim, result))
        summary.append(f'| {claim} | {headline(result)} | '
                       f'{{doc}}`{name} <pages/{name}>` |')
    # the pages in the table's order, hidden: the table links them
    summary += ['', '```{toctree}', ':hidden:', '',
                *(f'pages/{name}' for name in pages), '```']
    texts = {os.path.join('..', 'summary.md'): '\n'.join(summary) + '\n'}
    for name, (script, rows) in pages.items():
        lines = [f'# {rows[0][0]}', '']
        for claim, result in rows:
            if len(rows) > 1:
                lines += [f'**{claim}**', '']
            lines += [result, '']
        figure = os.path.join(RESULTS, f'{name}.png')
        if os.path.exists(figure):
            lines += [f'```{{image}} ../../../benchmarks/results/{name}.png',
                      f':alt: {name}', '```', '']
        lines += [f'Rerun with `python benchmarks/{script}` (it writes '
                  f'`benchmarks/results/{name}.json` and the figure).', '']
        texts[f'{name}.md'] = '\n'.join(lines)
    for file, text in texts.items():
        path = os.path.join(folder, file)
        if not os.path.exists(path) or open(path).read() != text:
            with open(path, 'w') as f:
                f.write(text)


write_results_pages()


def link_public_names(app, doctree):
    """Inline code on the guide's pages that is a public name (``DeltaConv``,
    ``recover()``) links to the name's API entry."""
    from sphinx.addnodes import pending_xref
    if app.env.docname.startswith('api/'):
        return
    for node in list(doctree.findall(nodes.literal)):
        if isinstance(node.parent, (nodes.reference, pending_xref)):
            continue
        text = node.astext()
        target = DOCUMENTED.get(text[:-2] if text.endswith('()') else text)
        if target is None:
            continue
        reference = pending_xref('', refdomain='py', reftype='obj',
                                 reftarget=target, refexplicit=True,
                                 refwarn=False)
        node.replace_self(reference)
        reference += node


def fix_source_backlinks(app, exception):
    """viewcode's "[docs]" links on the source pages take one module name
    per source file, so an object documented under another path (a name
    exported by its package beside one exported by the file itself) gets
    an anchor its page does not have; each such link is pointed at the id
    of that name on its page."""
    import re
    if exception is not None or app.builder.format != 'html':
        return
    out = app.outdir
    link = re.compile(r'(<a class="viewcode-back" href=")([^"#]+)#([^"]+)"')
    for folder, _, files in os.walk(os.path.join(out, '_modules')):
        for file in files:
            path = os.path.join(folder, file)
            text = open(path, encoding='utf-8').read()

            def fixed(match):
                target = os.path.normpath(os.path.join(folder, match[2]))
                page = open(target, encoding='utf-8').read() \
                    if os.path.exists(target) else ''
                if f'id="{match[3]}"' in page:
                    return match[0]
                name = match[3].rsplit('.', 1)[-1]
                ids = re.findall(rf'id="([\w.]+\.{re.escape(name)})"', page)
                return f'{match[1]}{match[2]}#{ids[0]}"' if ids \
                    else match[0]
            new = link.sub(fixed, text)
            if new != text:
                with open(path, 'w', encoding='utf-8') as f:
                    f.write(new)


def collapse_navigation(app, pagename, templatename, context, doctree):
    """The sidebar shows the branch of the page being read, not every page.

    furo renders the whole site tree into every page (collapse=False); with
    some 380 pages, most of them API entries, that took 186 of the build's
    265 profiled seconds and made each page carry the full tree. Collapsed,
    the sidebar lists the sections and, under the page's own section, its
    pages, as Sphinx's own themes do.
    """
    toctree = context.get('toctree')
    if toctree is not None:
        context['toctree'] = \
            lambda **options: toctree(**{**options, 'collapse': True})


def setup(app):
    # before furo's handler (priority 500), which renders the sidebar
    app.connect('html-page-context', collapse_navigation, priority=400)
    app.connect('missing-reference', link_external)
    app.connect('doctree-read', link_public_names)
    app.connect('build-finished', fix_source_backlinks)
