"""serpar's exceptions: one base class for the whole package; messages list the valid choices.

Every layer raises these (or, in vision, subclasses of them), so a caller catches
:class:`SerparError` for anything serpar refuses. This module is the bottom layer."""


class SerparError(Exception):
    """Base class for every error serpar raises."""


class ConfigError(SerparError, ValueError):
    """A configuration value is out of range or of the wrong kind."""


class UnknownNameError(SerparError, KeyError):
    """A name (camera, body, scene, check...) that does not exist; lists the valid ones."""

    def __init__(self, kind: str, name: object, valid: list[str] | tuple[str, ...]) -> None:
        self.kind, self.name, self.valid = kind, name, tuple(valid)
        super().__init__(f"unknown {kind} {name!r}; valid: {', '.join(self.valid)}")

    def __str__(self) -> str:  # KeyError would quote the message otherwise
        return self.args[0]


class LimitError(SerparError, ValueError):
    """A physical limit (stroke, hinge or joint angle, torque, solver tolerance) is violated.

    The message names the limit and its valid range, e.g.
    "leg 3 stroke 52.1 mm outside [0, 50.8] mm".
    """


class UnstableSimulation(SerparError, RuntimeError):
    """The integration broke down (NaN state, a MuJoCo warning, a constraint blow-up): the
    message names the reason and the simulated time."""


class IdentificationError(SerparError, ValueError):
    """Measurements that cannot identify the model: too few, non-finite, wrong shape, or a
    pose set that leaves parameter combinations unidentifiable."""
