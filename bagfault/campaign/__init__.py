"""Campaigns: one scenario swept over bags x fault parameters x seeds, on a local pool or a Ray cluster.

`model` and `loader` read and check the campaign file, `plan` expands it
into jobs (each with the hash it is stored under), `job` runs one job in
its own process, `engines` run jobs on a local pool or on Ray (`placement`
sends a bag's jobs to the nodes that hold it), `search`
bisects a parameter for its breaking point, `results` writes the tables and
the report.
"""

__all__ = [  # its public modules (imported when used, not here)
    'edit',
    'engines',
    'job',
    'loader',
    'model',
    'placement',
    'plan',
    'results',
    'runner',
    'search',
]
