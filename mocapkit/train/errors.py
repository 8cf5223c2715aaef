"""The configuration error every part of the engine raises: one line for the user, naming the key or file
(the CLI prints it and exits with code 2)."""


class ConfigError(ValueError):
    """A configuration problem; the message names the key or file."""
