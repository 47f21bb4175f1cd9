"""bagfault/report/page.py: array images as PNG pictures, and the plotly.js the page inlines."""

from __future__ import annotations

import numpy as np
import pytest
from support.html_check import png_pixels

from bagfault.report.page import Page, paint, png


def test_an_array_becomes_the_pixels_of_its_colour_scale_and_masks() -> None:
    values = np.array([[0.0, 10.0, np.nan], [5.0, np.inf, 2.5]])
    inf = np.isinf(values)
    pixels = png_pixels(png(paint(values, (0.0, 10.0), [(inf, '#ff00ff')])))
    assert pixels.shape == (2, 3, 4)
    assert pixels[0, 0].tolist() == [0x44, 0x01, 0x54, 255]  # the scale's bottom: Viridis' first stop
    assert pixels[0, 1].tolist() == [0xfd, 0xe7, 0x25, 255]  # its top: the last stop
    assert pixels[0, 2, 3] == 0  # no value: transparent
    assert pixels[1, 1].tolist() == [255, 0, 255, 255]  # inf: the mask's colour
    # 5.0 is half way: between the 5th and 6th of 10 evenly spaced stops (#26828e and #1f9e89)
    assert pixels[1, 0, :3].tolist() == [round((0x26 + 0x1f) / 2), round((0x82 + 0x9e) / 2), round((0x8e + 0x89) / 2)]


def test_figures_use_only_traces_the_inlined_bundle_draws() -> None:
    page = Page('t')
    page.figure([{'type': 'scatter', 'x': [0], 'y': [0]}], {})
    with pytest.raises(ValueError, match='scattergl'):
        page.figure([{'type': 'scattergl', 'x': [0], 'y': [0]}], {})
    html = page.render()
    assert 'plotly.js (cartesian - minified)' in html and len(html) < 1_600_000


def test_an_array_field_that_was_always_empty_is_a_blank_picture_not_a_broken_one() -> None:
    """A PNG must be at least one pixel high (the PNG specification): an array image without elements (every
    message held an empty array) is one transparent row over its time columns."""
    from bagfault.report.fields import ArrayImage
    from bagfault.report.html import _heatmap

    times = (np.arange(4) + 0.5) * 0.5
    empty = ArrayImage(times, np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4), dtype=bool),
                       np.zeros((0, 4), dtype=bool), 0.5)
    data, _ = _heatmap(empty, 'empty', 'element', [], (0.0, 1.0))
    pixels = png_pixels(data[0]['source'])
    assert pixels.shape == (1, 4, 4) and not pixels[..., 3].any()


def test_text_on_a_page_is_escaped_and_a_figure_cannot_close_its_script() -> None:
    """The page is made by templates/page.html.j2 with autoescape: a heading, a paragraph, an assertion message
    or a figure name holding HTML stays text; a figure's JSON holding `</script>` does not end its block."""
    from html.parser import HTMLParser

    from bagfault.report.page import macros

    page = Page('<title> & co')
    page.section('<h1>')
    page.paragraph('a <b>bold</b> claim')
    page.html(macros().assertions([{'state': 'failed', 'id': 'x', 'type': 't', 't': '', 'zoom': '',
                                    'message': '<img src=x onerror=alert(1)>'}]))
    page.figure([{'type': 'scatter', 'x': [0], 'y': [0], 'name': '</script><script>alert(1)</script>'}], {},
                name='"><b>')
    text = page.render()
    assert '<title>&lt;title&gt; &amp; co</title>' in text and '<h2>&lt;h1&gt;</h2>' in text
    assert '<p>a &lt;b&gt;bold&lt;/b&gt; claim</p>' in text and '&lt;img src=x onerror=alert(1)&gt;' in text
    assert 'data-name="&#34;&gt;&lt;b&gt;"' in text

    class Tags(HTMLParser):
        def __init__(self) -> None:
            super().__init__()
            self.tags: list[str] = []

        def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
            self.tags.append(tag)

    parser = Tags()
    parser.feed(text)
    assert parser.tags.count('script') == 3 and 'img' not in parser.tags and 'b' not in parser.tags
