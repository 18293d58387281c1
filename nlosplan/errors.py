"""Exceptions that carry a one-line message meant for the user, and the one unknown-key check.

The CLI turns :class:`UserError` into one line on stderr and exit code 2.
Everything else is a bug and keeps its traceback.
"""


class UserError(ValueError):
    """Invalid input from the user: bad value, unknown name, unreadable file.

    The message must name the bad value and say what is allowed, in one line.
    """


def check_keys(given, allowed, what: str, *, prefix: str = "", suffix: str = "") -> None:
    """Raise :class:`UserError` when ``given`` (keys of a mapping) holds names not in ``allowed``.

    The message is ``{prefix}unknown {what} {bad}{suffix}; allowed: {allowed}``:
    the unknown names sorted (the first 10, each cut to 40 characters), the
    allowed ones in the order given (sort them first for an alphabetical list).

    Parameters
    ----------
    given : iterable of str
        E.g. the keys of a configuration table.
    allowed : sequence of str
    what : str
        What the keys are, plural-aware, e.g. ``"sensor parameter(s)"``.
    prefix, suffix : str
        Context before ``unknown`` (e.g. the file) and after the names (e.g. the table).
    """
    bad = sorted(set(given) - set(allowed))
    if bad:
        names = [str(b) if len(str(b)) <= 40 else str(b)[:40] + "..." for b in bad[:10]]   # never a huge line
        more = f" and {len(bad) - 10} more" if len(bad) > 10 else ""
        raise UserError(f"{prefix}unknown {what} {', '.join(names)}{more}{suffix}; allowed: {', '.join(allowed)}")
