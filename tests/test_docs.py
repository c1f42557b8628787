"""The API reference's inputs: every module with public names (an
``__all__``) has a section in ``docs/api_pages.py``, and every public name
has a docstring of its own (a constant: a ``#:`` comment where it is
defined), so that the generated pages are never empty. The site itself is
built by ``make docs`` (warnings are errors), a step of ``.ci/run``, which
then runs ``docs/check_site.py`` on it (nothing loaded from another host,
every link inside the site reaching its page and anchor, no typographic
dash where a command's ``--`` belongs); its checks are tested here on
pages written to fail them."""
import importlib
import inspect
import os
import pkgutil
import sys
import warnings

import pytest

import tg_intrinsic

DOCS = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'docs')


def modules_with_public_names():
    with warnings.catch_warnings():  # the deprecated module paths warn
        warnings.simplefilter('ignore', DeprecationWarning)
        found = [tg_intrinsic]
        for info in pkgutil.walk_packages(tg_intrinsic.__path__,
                                          'tg_intrinsic.'):
            found.append(importlib.import_module(info.name))
    return [m for m in found if hasattr(m, '__all__')]


def api_pages():
    sys.path.insert(0, DOCS)
    try:
        return importlib.import_module('api_pages').API_PAGES
    finally:
        sys.path.remove(DOCS)


def test_every_module_with_public_names_has_an_api_section():
    listed = [m for modules in api_pages().values() for m in modules]
    assert len(listed) == len(set(listed))
    missing = sorted({m.__name__ for m in modules_with_public_names()}
                     - set(listed))
    assert not missing, (f"add these modules to docs/api_pages.py: "
                         f"{missing}")
    for name in listed:  # and no stale entry
        assert hasattr(importlib.import_module(name), '__all__'), name


def attribute_docs():
    """``{(module name, attribute)}`` documented by a ``#:`` comment."""
    from sphinx.pycode import ModuleAnalyzer
    documented = set()
    for module in modules_with_public_names():
        for (_, name) in ModuleAnalyzer.for_module(
                module.__name__).find_attr_docs():
            documented.add(name)
    return documented


def test_every_public_name_has_a_docstring():
    pytest.importorskip('sphinx')
    documented = attribute_docs()
    undocumented = []
    for module in modules_with_public_names():
        for name in module.__all__:
            obj = getattr(module, name)
            if inspect.ismodule(obj):
                continue
            if inspect.isclass(obj) or inspect.isroutine(obj):
                ok = bool((obj.__doc__ or '').strip())
            else:  # a constant: its #: comment
                ok = name in documented
            if not ok:
                undocumented.append(f'{module.__name__}.{name}')
    assert not undocumented, f"no docstring: {undocumented}"


def test_the_version_is_defined_once():
    from tg_intrinsic.cli import build_parser
    root = os.path.join(DOCS, '..')
    setup = open(os.path.join(root, 'setup.py')).read()
    assert "version=VERSION" in setup and tg_intrinsic.__version__ not in \
        setup
    changelog = open(os.path.join(root, 'CHANGELOG.md')).read()
    assert f'## {tg_intrinsic.__version__}' in changelog
    with pytest.raises(SystemExit) as exit_info:
        build_parser().parse_args(['--version'])
    assert exit_info.value.code == 0



def test_every_public_forward_says_its_arguments_and_shapes():
    """A class page shows the class's own members with their own
    docstrings (an undocumented override shows nothing), so every public
    module's forward documents its arguments and what it returns."""
    import torch
    missing = []
    for module in modules_with_public_names():
        for name in module.__all__:
            obj = getattr(module, name)
            if not (inspect.isclass(obj) and issubclass(obj, torch.nn.Module)
                    and 'forward' in vars(obj)):
                continue
            doc = inspect.getdoc(vars(obj)['forward']) or ''
            arguments = len(inspect.signature(obj.forward).parameters) > 1
            if not doc or (arguments and 'Args:' not in doc) or \
                    'Returns:' not in doc:
                missing.append(f'{module.__name__}.{name}.forward')
    assert not missing, f"forward without Args/Returns: {sorted(set(missing))}"


def check_site():
    sys.path.insert(0, DOCS)
    try:
        return importlib.import_module('check_site')
    finally:
        sys.path.remove(DOCS)


def write_site(root, pages):
    for name, body in pages.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(f'<html><head></head><body>{body}</body></html>',
                        encoding='utf-8')


GOOD = {
    'index.html': '<h1 id="top">Top</h1><a href="api/nn.html#deltaconv">'
                  'DeltaConv</a><a href="https://pyg.org">PyG</a>'
                  '<script src="_static/mathjax/tex-chtml.js"></script>'
                  '<pre>tg-intrinsic demo --out DIR</pre>',
    'api/nn.html': '<dl id="deltaconv"></dl><a href="../index.html#top">'
                   'up</a><a href="#deltaconv">here</a>',
    '_static/mathjax/tex-chtml.js': '',
}


def test_check_site_passes_a_good_site(tmp_path):
    write_site(tmp_path, GOOD)
    assert check_site().problems(str(tmp_path)) == []


@pytest.mark.parametrize('page,body,needle', [
    ('math.html', '<script src="https://cdn.jsdelivr.net/npm/mathjax@3/'
     'es5/tex-chtml.js"></script>', 'from another host'),
    ('style.html', '<link rel="stylesheet" href="//fonts.example.org/a.css">',
     'from another host'),
    ('lost.html', '<a href="api/io.html">io</a>', 'reaches no file'),
    ('anchor.html', '<a href="api/nn.html#DeltaConv.forward">forward</a>',
     "reaches no element '#DeltaConv.forward'"),
    ('usage.html', '<p>usage: example.py [\u2013out DIR]</p>',
     "a typographic dash where '--' belongs"),
])
def test_check_site_finds_each_problem(tmp_path, page, body, needle):
    write_site(tmp_path, {**GOOD, page: body})
    found = check_site().problems(str(tmp_path))
    assert len(found) == 1 and found[0].startswith(page) and \
        needle in found[0], found
