"""Assertions: expected outcomes checked on the engine's clock."""
