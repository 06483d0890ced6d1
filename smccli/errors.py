"""Errors the user can act on. The CLI maps each to a one-line message and an exit code.

A message names the file, the thing, what was expected and what was found, e.g.
``demo.mcap: topic /camera/depth missing (scene pick_place needs it)``.
"""


class SmcError(Exception):
    """Base of every expected failure; ``exit_code`` is what the CLI returns."""

    exit_code = 2


class SceneError(SmcError):
    """A scene name, scene file or MJCF model is unknown or invalid."""


class ScriptError(SmcError):
    """A teleop script is invalid or asks for something impossible (unknown object, unreachable)."""


class LogError(SmcError):
    """A log file is missing, not MCAP, lacks a topic, or holds values that make no sense."""


class TreeError(SmcError):
    """A tree file is missing, corrupt, of another schema version or built with other params."""


class OutputError(SmcError):
    """An output cannot be written: its folder is missing or read-only, or it is a folder."""


class OutputExistsError(OutputError):
    """An output file exists and ``--force`` was not given."""
