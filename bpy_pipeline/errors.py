"""The one error type users see.

Anything the user can fix (a config key, a file, an object in their scene) raises
:class:`InputError` with a one-line message that names the key, object or file and what is
allowed. ``run.py`` prints it and exits with code 2; nothing half-written is left behind.
"""


class InputError(Exception):
    """Bad user input: a one-line message naming the key, object or file and what is allowed."""

    exit_code = 2
