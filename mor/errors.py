"""The project's error types: each one carries a single line a user can act on."""


class MorError(Exception):
    """Base class: the message is one line that names the file or field and says what to do."""


class ConfigError(MorError, ValueError):
    """An invalid parameter (unknown key, out-of-range value, impossible configuration)."""


class RenderBackendError(MorError, RuntimeError):
    """No OpenGL backend could be created for headless rendering."""
