"""Errors and warnings that carry a one-line message meant for the user."""


class WiseError(ValueError):
    """Bad input: the message says what is wrong and what to do.

    The command line prints the message as one line and exits with code 2.
    """


class WiseWarning(UserWarning):
    """A warning meant for the user, printed by the command line as one line."""


def size_text(width: int, height: int) -> str:
    """An image size as ``"96x120"``: width x height, in every message that states one."""
    return f"{width}x{height}"
