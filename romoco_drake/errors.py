"""User-facing errors: one line that says which file and key are wrong."""


class RomocoError(Exception):
    """A mistake the user can fix (bad config, unknown name, unreadable file).

    The CLI prints ``str(error)`` as one line and exits with code 2; no traceback.
    """


class ConfigError(RomocoError):
    """A YAML file is missing a key, has an extra or mistyped key, or a bad value."""

    def __init__(self, path, key: str, message: str):
        self.path = str(path)
        self.key = key
        where = f"{self.path}: {key}: " if key else f"{self.path}: "
        super().__init__(where + message)
