"""The one exception type the core raises for bad input or a failed computation."""


class ConformalError(ValueError):
    """Bad input or an impossible request. The message says what is wrong and what to do."""
