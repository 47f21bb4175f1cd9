"""Generated sections (Hypothesis): every declared section read with any YAML value under any of its keys. The
reader never raises; each key given is read or refused, a refused one with a problem at its path; what is read
is of the declared type and within the declared range (the declaration is the oracle: `Key` in schema.py)."""

from __future__ import annotations

import math
from typing import Any

from hypothesis import given, settings
from hypothesis import strategies as st

from bagfault.spec import sections
from bagfault.spec.reader import Reader
from bagfault.spec.sections import Section

SECTIONS = sorted((s for s in vars(sections).values() if isinstance(s, Section)), key=lambda s: s.name)
SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-2**70, 2**70), st.floats(allow_nan=True),
                    st.sampled_from(['', 'x', '1', '-1', '0.5', '+1', '0x10', '.inf', 'nan', 'yes', 'off', 'true']))
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                       st.dictionaries(st.sampled_from(['a', 'codes']), inner,
                                                                       max_size=2)), max_leaves=5)


def _edges(key: Any) -> list[Any]:
    """Values at and beside the declared bounds, as numbers and as text."""
    ends = [b for b in (key.minimum, key.maximum) if b is not None]
    found = [e + d for e in ends for d in (-1, -0.5, 0, 0.5, 1)]
    return found + [str(v) for v in found]


@st.composite
def nodes(draw: st.DrawFn) -> tuple[Section, dict[str, Any]]:
    section = draw(st.sampled_from(SECTIONS))
    names = [k.name for k in section.keys] + ['not_declared']
    node = {}
    for name in draw(st.lists(st.sampled_from(names), max_size=6, unique=True)):
        key = section.key(name)
        edges = _edges(key) if key is not None else []
        node[name] = draw(st.one_of(VALUES, st.sampled_from(edges)) if edges else VALUES)
    return section, node


def _within(key: Any, value: Any) -> bool:
    if key.type not in ('number', 'integer', 'seconds'):
        return True
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return False
    if key.type == 'integer' and not isinstance(value, int):
        return False
    low, high = key.minimum, key.maximum
    return (low is None or value > low or (value == low and not key.exclusive)) and (high is None or value <= high)


@settings(max_examples=400, deadline=None)
@given(case=nodes())
def test_a_section_reads_or_refuses_every_key_it_is_given(case: tuple[Section, dict[str, Any]]) -> None:
    section, node = case
    problems: list[tuple[Any, str]] = []
    read = Reader(lambda path, message: problems.append((path, message)),
                  lambda path, message: None).read(section, node, ('here',))
    assert read is not None  # a mapping is always read
    declared = {k.name: k for k in section.keys}
    assert set(read.values) <= set(declared) and read.refused <= read.given <= set(node)
    for name in read.refused:
        assert any(path[:2] == ('here', name) for path, _ in problems), (name, problems)
    for name in read.given - read.refused:
        key, value = declared[name], read.values.get(name)
        assert name in read.values
        if key.choices:
            assert value in key.choices
        elif key.type == 'boolean':
            assert isinstance(value, bool)
        elif key.type in ('list', 'mapping'):
            assert isinstance(value, list if key.type == 'list' else dict)
        else:
            assert _within(key, value), (name, key, value)
