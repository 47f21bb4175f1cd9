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
