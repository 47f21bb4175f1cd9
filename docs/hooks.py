"""mkdocs hook: the scenario reference's tables come from bagfault's own schema, so they never drift."""

from __future__ import annotations

from typing import Any

MARKER = '<!-- generated: schema -->'


def on_page_markdown(markdown: str, page: Any, **_: Any) -> str:
    """Replace the marker with the tables of every injector and assertion type."""
    if MARKER not in markdown:
        return markdown
    from bagfault.report.schema import render_markdown

    return markdown.replace(MARKER, render_markdown())
