"""MkDocs hook: the docstrings' reStructuredText roles (``:class:`Vehicle```, ``:mod:`…```),
which mkdocstrings renders as the role's name followed by the code, shown as the code alone
(``:func:`~a.b.c``` as ``c``, as Sphinx would) in the generated API pages."""

from __future__ import annotations

import re

_ROLE = re.compile(r":(?:mod|class|func|meth|attr|data|exc|obj):<code>(?:~(?:[\w]+\.)*)?")


def on_page_content(html: str, page, config, files) -> str:  # MkDocs passes these by name
    return _ROLE.sub("<code>", html)
