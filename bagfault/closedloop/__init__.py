"""Closed loop (`bagfault test`): the system under test started, fed the faulty bag on sim time, recorded, judged.

`domain` leases a private ROS domain, `process` starts and stops the system
in its own process group, `link` is the live pass that also hears the
system, `runner` puts them together (and repeats them).
"""

__all__ = [  # its public modules (imported when used, not here)
    'actions',
    'clocks',
    'domain',
    'isolation',
    'link',
    'links',
    'process',
    'repeat',
    'runner',
    'watchdog',
]
