"""Reusable fault primitives: combining active faults, drop, noise, rotations."""
