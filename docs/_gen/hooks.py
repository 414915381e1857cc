"""mkdocs hook: the code's and the docs' section references become links; Sphinx roles read as code.

ringfit cites its reference pages as ``docs/physics.md §4.3`` or ``formats.md §13.1``
(in docstrings, the notebooks and the pages themselves). On the site each such
reference links to the section: the section numbers are read from the headings of
``physics.md`` and ``formats.md`` (``## 4.`` / ``### 4.3``) and the anchors are the
ones the ``toc`` extension gives those headings. A reference to a section that does
not exist is a warning (a failure under ``mkdocs build --strict``); a subsection without a
heading of its own (``§6.4`` where §6 has none) links to its section, said at INFO level.

Docstrings written before the site name objects with Sphinx roles (``:func:`~ringfit.x.f```);
on the site the role is dropped and the name stays code (``~`` keeps its last part).
"""

from __future__ import annotations

import logging
import re

from markdown.extensions.toc import slugify
from mkdocs.utils import get_relative_url

log = logging.getLogger("mkdocs.plugins.ringfit_links")

PAGES = ("physics", "formats")
_HEADING = re.compile(r"^#{2,4}\s+(\d+(?:\.\d+)*)\.?\s+(.*?)\s*$", re.M)
# `docs/physics.md §4.3`, docs/physics.md §4.3, `physics.md` §6, formats.md (no section) — in rendered HTML
_REF = re.compile(
    r"(?P<open><code>)?(?:docs/)?(?P<page>physics|formats)\.md(?P<close1></code>)?"
    r"(?:(?P<sp>\s|&nbsp;)(?P<open2><code>)?§(?P<sec>\d+(?:\.\d+)*)(?P<close2></code>)?)?"
    r"(?P<close3></code>)?"
)
_ROLE = re.compile(r":(?:func|class|meth|data|mod|attr|exc|obj):<code>(~?)([^<]+)</code>")
_sections: dict[str, dict[str, str]] = {}


def on_files(files, config):
    """Read the section numbers and their anchors from the two reference pages."""
    for page in PAGES:
        f = files.get_file_from_path(f"{page}.md")
        if f is None:
            log.warning("cross-links: docs/%s.md is missing", page)
            continue
        text = f.content_string
        _sections[page] = {}
        for m in _HEADING.finditer(text):
            title = m.group(0).lstrip("#").strip()
            _sections[page][m.group(1)] = slugify(title, "-")
    return files


def _link(match: re.Match, page_url: str, where: str) -> str:
    page, sec = match.group("page"), match.group("sec")
    target = f"{page}.html" if not sec else None
    if sec:
        anchors = _sections.get(page, {})
        key = sec
        while key not in anchors and "." in key:  # §6.4 without a heading of its own: its section, §6
            key = key.rsplit(".", 1)[0]
        if key not in anchors:
            log.warning("cross-links: %s cites %s.md §%s, which has no such section", where, page, sec)
            return match.group(0)
        if key != sec:
            log.info("cross-links: %s cites %s.md §%s, which has no heading; linked to §%s", where, page, sec, key)
        target = f"{page}.html#{anchors[key]}"
    href = get_relative_url(target, page_url)
    text = f"{page}.md" + (f" §{sec}" if sec else "")
    return f'<a href="{href}"><code>{text}</code></a>'


def _outside_tags_and_links(html: str):
    """Split ``html`` into (is_text, chunk): text outside tags, ``<a>`` elements and ``<pre>`` blocks."""
    pos = 0
    for m in re.finditer(r"<a\b.*?</a>|<pre\b.*?</pre>|<[^>]+>", html, re.S):
        if m.start() > pos:
            yield True, html[pos:m.start()]
        yield m.group(0) in ("<code>", "</code>"), m.group(0)
        pos = m.end()
    if pos < len(html):
        yield True, html[pos:]


def on_page_content(html, page, config, files):
    """Turn every section reference in a page's HTML (outside links and code blocks) into a link."""
    html = _ROLE.sub(lambda m: f"<code>{m.group(2).rsplit('.', 1)[-1] if m.group(1) else m.group(2)}</code>", html)
    if not _sections:
        return html
    # join text and inline <code> tags so that `<code>docs/physics.md §4.3</code>` is one unit
    chunks, out, buf = list(_outside_tags_and_links(html)), [], []
    for is_text, chunk in chunks:
        if is_text:
            buf.append(chunk)
            continue
        out.append(_REF.sub(lambda m: _link(m, page.url, page.file.src_uri), "".join(buf)))
        buf = []
        out.append(chunk)
    out.append(_REF.sub(lambda m: _link(m, page.url, page.file.src_uri), "".join(buf)))
    return "".join(out)
