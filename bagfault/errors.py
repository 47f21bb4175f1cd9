"""Error base class: every error bagfault raises on purpose derives from it."""

from __future__ import annotations


class BagfaultError(Exception):
    """A problem with the user's input, scenario, or environment.

    The command line prints it as one line and exits with code 2; anything
    else that escapes is a bug in bagfault.
    """
