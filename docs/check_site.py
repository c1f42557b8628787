"""Checks the built site as a reader meets it, after Sphinx (``make docs``
runs it; ``tests/test_docs.py`` tests each check on pages written to fail
it):

- no page loads a script, a style sheet or an image from another host
  (the site works offline, MathJax included);
- every link inside the site reaches a page that exists and, with a
  ``#fragment``, an element of that id on it;
- no typographic dash stands where a command line's ``--`` belongs (text
  such as ``–out``, which a pasted command would not accept).

    python docs/check_site.py docs/_build/html     # one line per problem
"""
import os
import re
import sys
from html.parser import HTMLParser
from typing import Dict, List, Set, Tuple
from urllib.parse import unquote, urlsplit

# a dash Sphinx's smart quotes made of '--' or '---', before an option name
MANGLED_OPTION = re.compile('[\u2013\u2014](?=[a-z])')
# what a page loads, as opposed to what it links to
LOADED = {('script', 'src'), ('link', 'href'), ('img', 'src'),
          ('source', 'src'), ('iframe', 'src')}


class _Page(HTMLParser):
    """The ids, loaded resources, links and visible text of one page."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.ids: Set[str] = set()
        self.loaded: List[str] = []
        self.links: List[str] = []
        self.text: List[str] = []
        self._hidden = 0

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if 'id' in attrs:
            self.ids.add(attrs['id'])
        if tag == 'a' and 'name' in attrs:
            self.ids.add(attrs['name'])
        for element, attribute in LOADED:
            if tag == element and attrs.get(attribute) and (
                    tag != 'link' or attrs.get('rel') not in (
                        'canonical', 'next', 'prev', 'index', 'search')):
                self.loaded.append(attrs[attribute])
        if tag == 'a' and attrs.get('href'):
            self.links.append(attrs['href'])
        if tag in ('script', 'style'):
            self._hidden += 1

    def handle_endtag(self, tag):
        if tag in ('script', 'style'):
            self._hidden -= 1

    def handle_data(self, data):
        if not self._hidden:
            self.text.append(data)


def _remote(url: str) -> bool:
    parts = urlsplit(url)
    return bool(parts.netloc) or parts.scheme in ('http', 'https')


def read_site(root: str) -> Dict[str, _Page]:
    """Every HTML page under ``root``, parsed, by path relative to it."""
    pages = {}
    for folder, _, files in os.walk(root):
        for name in files:
            if name.endswith('.html'):
                path = os.path.join(folder, name)
                page = _Page()
                page.feed(open(path, encoding='utf-8').read())
                pages[os.path.relpath(path, root)] = page
    return pages


def problems(root: str) -> List[str]:
    """What is wrong with the site built in ``root``, one line each."""
    pages = read_site(root)
    found = []
    for name, page in sorted(pages.items()):
        for url in page.loaded:
            if _remote(url):
                found.append(f'{name}: loads {url} from another host')
        for url in page.links:
            reason = _broken_link(root, pages, name, url)
            if reason:
                found.append(f'{name}: link {url} {reason}')
        text = ''.join(page.text)
        for match in MANGLED_OPTION.finditer(text):
            context = text[max(0, match.start() - 30):match.end() + 20]
            found.append(f"{name}: a typographic dash where '--' belongs: "
                         f"{' '.join(context.split())!r}")
    return found


def _broken_link(root: str, pages: Dict[str, _Page], name: str,
                 url: str) -> str:
    """Why ``url`` on page ``name`` leads nowhere ('' when it is fine)."""
    parts = urlsplit(url)
    if parts.scheme or parts.netloc:
        return ''  # another site's link: followed by the reader, not here
    target = os.path.normpath(os.path.join(
        os.path.dirname(name), unquote(parts.path))) if parts.path else name
    if parts.path and not os.path.exists(os.path.join(root, target)):
        return 'reaches no file'
    if os.path.isdir(os.path.join(root, target)):
        target = os.path.join(target, 'index.html')
    fragment = unquote(parts.fragment)
    if fragment and target in pages and fragment not in pages[target].ids:
        return f"reaches no element '#{fragment}' on {target}"
    return ''


def main(argv: Tuple[str, ...]) -> int:
    if len(argv) != 1 or not os.path.isdir(argv[0]):
        print('usage: python docs/check_site.py BUILT_HTML_FOLDER',
              file=sys.stderr)
        return 2
    found = problems(argv[0])
    for line in found:
        print(line, file=sys.stderr)
    print(f'check_site: {len(found)} problem(s) in {argv[0]}')
    return 1 if found else 0


if __name__ == '__main__':
    sys.exit(main(tuple(sys.argv[1:])))
