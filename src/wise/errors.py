"""Errors that carry a one-line message meant for the user."""


class WiseError(ValueError):
    """Bad input: the message says what is wrong and what to do.

    The command line prints the message as one line and exits with code 2.
    """
