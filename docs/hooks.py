"""MkDocs hook: show the Sphinx cross-reference roles of the numpydoc docstrings
(``:func:`x```, ``:class:`x```, ...) as plain code, as Sphinx would show their text."""

import re

_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|attr|data|exc|obj):(<code>)")


def on_page_content(html, **kwargs):
    return _ROLE.sub(r"\1", html)
