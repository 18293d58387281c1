"""Exceptions that carry a one-line message meant for the user.

The CLI turns :class:`UserError` into one line on stderr and exit code 2.
Everything else is a bug and keeps its traceback.
"""


class UserError(ValueError):
    """Invalid input from the user: bad value, unknown name, unreadable file.

    The message must name the bad value and say what is allowed, in one line.
    """
