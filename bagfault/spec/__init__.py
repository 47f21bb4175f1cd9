"""A scenario as data: the records the loader makes (model), its system_under_test section (system) and the
located YAML they are read from (yamlnodes). Below every layer that reads a scenario; `bagfault.scenario` loads
and validates files into these records."""

__all__ = [  # its public modules (imported when used, not here)
    'model',
    'names',
    'reader',
    'sections',
    'system',
    'yamlnodes',
]
