"""bagfault: record-and-replay fault injection for ROS 2."""

from __future__ import annotations

from bagfault.errors import BagfaultError

__version__ = '0.1.0'

__all__ = ['BagfaultError', '__version__']
