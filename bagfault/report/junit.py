"""JUnit XML: one testcase per assertion, failures with their message (CI viewers).

By default the file is valid under Jenkins' junit-10.xsd (the xunit plugin's
schema) and the common one the tests ship: a testcase has only `name`,
`classname` and `time`, so the scenario file is a suite property and each
testcase's text starts with `file:line:`. `extended` adds `file` and `line`
attributes on each testcase, which GitHub's and GitLab's readers link and
junit-10 refuses. `time` is wall time (the run's on the suite, the
assertion's evaluation on a testcase). A run that could not start still gets
a file: one testcase with an `error` saying why.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any


def _document(root: ET.Element) -> str:
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding='unicode') + '\n'


def render(report: dict[str, Any], *, extended: bool = False) -> str:
    """JUnit XML text: <testsuites><testsuite><testcase .../></testsuite></testsuites>."""
    assertions = report['assertions']
    failures = sum(a['state'] != 'passed' for a in assertions)
    wall = report['time'].get('wall_s') or 0.0
    suite_name = report['scenario']['name']
    root = ET.Element('testsuites', name='bagfault', tests=str(len(assertions)), failures=str(failures),
                      errors='0', time=f'{wall:.3f}')
    suite = ET.SubElement(root, 'testsuite', name=suite_name, tests=str(len(assertions)), failures=str(failures),
                          errors='0', skipped='0', time=f'{wall:.3f}')
    properties = ET.SubElement(suite, 'properties')
    for name, value in (('scenario', report['scenario']['file']), ('seed', report['seed']),
                        ('inputs', ', '.join(report['inputs'])),
                        ('output', report['output'] or ''), ('bagfault', report['tool']['version']),
                        ('bag_duration_s', report['time']['duration_s'])):
        ET.SubElement(properties, 'property', name=name, value=str(value))
    classname = 'bagfault.' + suite_name.rsplit('.', 1)[0]
    for a in assertions:
        t = a['t_s'] if a['t_s'] is not None else 0.0
        place = {'file': report['scenario']['file']} | ({'line': str(a['line'])} if a.get('line') else {})
        where = ':'.join(place.values())
        case = ET.SubElement(suite, 'testcase', {'name': a['id'], 'classname': classname,
                                                 'time': f'{a.get("wall_s", 0.0):.6f}', **(place if extended else {})})
        if a['state'] != 'passed':
            failure = ET.SubElement(case, 'failure', message=a['message'], type=a['type'])
            failure.text = f'{where}: {a["type"]} {a["id"]} {a["state"]} at bag time {t:.3f} s: {a["message"]}'
        else:
            ET.SubElement(case, 'system-out').text = f'{where}: {a["message"]} (bag time {t:.3f} s)'
    return _document(root)


def render_error(scenario: str, reason: str, wall: float, *, extended: bool = False) -> str:
    """The file of a run that could not start or finish (exit 2): one testcase with an `error`."""
    name = scenario.replace('\\', '/').rsplit('/', 1)[-1] or 'bagfault'
    root = ET.Element('testsuites', name='bagfault', tests='1', failures='0', errors='1', time=f'{wall:.3f}')
    suite = ET.SubElement(root, 'testsuite', name=name, tests='1', failures='0', errors='1', skipped='0',
                          time=f'{wall:.3f}')
    place = {'file': scenario, 'line': '1'} if extended else {}
    case = ET.SubElement(suite, 'testcase', {'name': 'run', 'classname': 'bagfault.' + name.rsplit('.', 1)[0],
                                             'time': f'{wall:.3f}', **place})
    error = ET.SubElement(case, 'error', message=reason, type='could not run')
    error.text = f'{scenario}: {reason}'
    return _document(root)
