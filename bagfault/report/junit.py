"""JUnit XML: one testcase per assertion, failures with their message (CI viewers)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Any


def render(report: dict[str, Any]) -> str:
    """JUnit XML text: <testsuites><testsuite><testcase .../></testsuite></testsuites>."""
    assertions = report['assertions']
    failures = sum(a['state'] != 'passed' for a in assertions)
    duration = report['time']['duration_s'] or 0.0
    suite_name = report['scenario']['name']
    root = ET.Element('testsuites', name='bagfault', tests=str(len(assertions)), failures=str(failures),
                      errors='0', time=f'{duration:.3f}')
    suite = ET.SubElement(root, 'testsuite', name=suite_name, tests=str(len(assertions)), failures=str(failures),
                          errors='0', skipped='0', time=f'{duration:.3f}')
    properties = ET.SubElement(suite, 'properties')
    for name, value in (('seed', report['seed']), ('inputs', ', '.join(report['inputs'])),
                        ('output', report['output'] or ''), ('bagfault', report['tool']['version'])):
        ET.SubElement(properties, 'property', name=name, value=str(value))
    classname = 'bagfault.' + suite_name.rsplit('.', 1)[0]
    for a in assertions:
        t = a['t_s'] if a['t_s'] is not None else 0.0
        case = ET.SubElement(suite, 'testcase', name=a['id'], classname=classname, time=f'{max(t, 0.0):.3f}')
        if a['state'] != 'passed':
            failure = ET.SubElement(case, 'failure', message=a['message'], type=a['type'])
            failure.text = f'{a["type"]} {a["id"]} {a["state"]} at bag time {t:.3f} s: {a["message"]}'
        else:
            ET.SubElement(case, 'system-out').text = a['message']
    ET.indent(root)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding='unicode') + '\n'
