"""Exceptions of the :mod:`sim` package: one base class, messages list valid choices."""


class SimError(Exception):
    """Base class for every error raised by :mod:`sim`."""


class ConfigError(SimError, ValueError):
    """A configuration value is out of range or of the wrong kind."""


class UnknownNameError(SimError, KeyError):
    """A name (camera, body, scene, check...) that does not exist; lists the valid ones."""

    def __init__(self, kind: str, name: object, valid: list[str] | tuple[str, ...]) -> None:
        self.kind, self.name, self.valid = kind, name, tuple(valid)
        super().__init__(f"unknown {kind} {name!r}; valid: {', '.join(self.valid)}")

    def __str__(self) -> str:  # KeyError would quote the message otherwise
        return self.args[0]


class LimitError(SimError, ValueError):
    """A physical limit (stroke, hinge or joint angle, torque, solver tolerance) is violated.

    The message names the limit and its valid range, e.g.
    "leg 3 stroke 52.1 mm outside [0, 50.8] mm".
    """


class UnstableSimulation(SimError, RuntimeError):
    """The integration broke down (NaN state, a MuJoCo warning, a constraint blow-up): the
    message names the reason and the simulated time."""
