"""The installed project's metadata, as an index would publish it (#31 point 6)."""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

from trove_classifiers import classifiers as known
from trove_classifiers import deprecated_classifiers

ROOT = Path(__file__).resolve().parents[1]


def test_the_declared_license_is_the_license_file_and_every_classifier_is_pypi_s() -> None:
    meta = importlib.metadata.metadata('bagfault')
    assert meta['License-Expression'] == 'Apache-2.0'
    assert meta.get_all('License-File') == ['LICENSE']
    text = (ROOT / 'LICENSE').read_text(encoding='utf-8')
    assert text.split()[:4] == ['Apache', 'License', 'Version', '2.0,']  # the text SPDX names Apache-2.0
    assert 'TERMS AND CONDITIONS FOR USE, REPRODUCTION, AND DISTRIBUTION' in text
    assert meta['Author']
    found = meta.get_all('Classifier') or []
    assert found and set(found) <= known and not set(found) & set(deprecated_classifiers)
    assert not any(c.startswith('License ::') for c in found)  # a license expression replaces them (PEP 639)
    assert any(c.startswith('Framework :: Pytest') for c in found)  # the plugin entry point below
    plugins = [e for e in importlib.metadata.entry_points(group='pytest11') if e.value.startswith('bagfault')]
    assert plugins
