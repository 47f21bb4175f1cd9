"""Injectors: one module per type, a base class, and the entry-point registry."""

from __future__ import annotations

from bagfault.injectors.base import ActiveFault, Injector, RawMessage, ServiceInjector
from bagfault.injectors.registry import get_injector_type, injector_types

__all__ = ['ActiveFault', 'Injector', 'RawMessage', 'ServiceInjector', 'get_injector_type', 'injector_types']
