"""Human and machine readable output: terminal summary, markdown, JSON, JUnit, HTML."""

__all__ = [  # its public modules (imported when used, not here)
    'fields',
    'files',
    'html',
    'info',
    'json_report',
    'junit',
    'latency',
    'markdown',
    'model',
    'page',
    'rates',
    'schema',
    'summary',
]
