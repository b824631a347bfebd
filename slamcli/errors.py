"""Exception hierarchy. Every error a user can cause is a :class:`SlamcliError`; the CLI turns it into a
one-line message and a non-zero exit, never a traceback."""


class SlamcliError(Exception):
    """Base class: the message must be one line that names the file/field and what is wrong."""


class ConfigError(SlamcliError):
    """Bad parameters, overrides or experiment files."""


class SchemaError(SlamcliError):
    """A data or result file that is not what the schema says."""


class PluginError(SlamcliError):
    """A solver plugin that is unknown or cannot be loaded."""


class SolverError(SlamcliError):
    """A solver that cannot run on the given inputs."""
