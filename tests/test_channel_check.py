"""The channel check: an effect acting on one of a joint's two torque channels alone (a sensor
gain) is told apart from a cause that moves the joint's torque in both (an encoder's scale)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pytest
from numpy.typing import NDArray

from serpar.diagnosis.channel_check import MIRROR_SHARE, channel_check

N = 4000
SIGMA = np.array([0.005, 0.02])
"""[N m] the sensor's and the drive's noise: the drive's is the larger, as on the Panda."""


@dataclass
class _View:
    scale: NDArray[np.float64]


class _OneJoint:
    """One joint's torque through its sensor (channel 0) and its drive (channel 1); the only
    effect, ``gain``, scales the sensor's torque (a torque-sensor gain error)."""

    channels = ("tau_J1", "tau_J_d1")
    sibling_channels = (1, 0)

    def __init__(self, cause_in_drive: float, tare: float = 0.3) -> None:
        rng = np.random.default_rng(0)
        t = np.linspace(0.0, 40.0, N)
        self.torque = 8.0 + 3.0 * np.sin(0.7 * t) + np.sin(2.3 * t)  # gravity mostly
        cause = 0.01 * self.torque  # the sensor's 1 % gain, or a shift of the joint's torque
        self.link = cause + tare + SIGMA[0] * rng.standard_normal(N)
        self.drive = cause_in_drive * cause + SIGMA[1] * rng.standard_normal(N)

    def residual(self, params: Mapping[str, NDArray[np.float64]], rows: NDArray[np.int64]
                 ) -> NDArray[np.float64]:
        gain = float(params.get("gain", np.zeros(1))[0])
        tare = float(params.get("tare", np.zeros(1))[0])
        link = self.link[rows] - gain * self.torque[rows] - tare
        return np.column_stack([link / SIGMA[0], self.drive[rows] / SIGMA[1]]).ravel()

    def in_units(self, rows: NDArray[np.int64]) -> _View:
        return _View(np.tile(SIGMA, len(rows)))


def _fitted(family: _OneJoint) -> dict[str, NDArray[np.float64]]:
    """The sensor's gain and tare by least squares on its own channel (what the fit does)."""
    a = np.column_stack([family.torque, np.ones(N)])
    gain, tare = np.linalg.lstsq(a, family.link, rcond=None)[0]
    return {"gain": np.array([gain]), "tare": np.array([tare])}


def test_a_sensor_gain_the_drive_does_not_show_passes() -> None:
    family = _OneJoint(cause_in_drive=0.0)
    check = channel_check(family, _fitted(family), "gain", np.arange(N))
    assert check is not None and check.material == ("tau_J1",)
    assert check.mirrored == () and check.reasons() == []


@pytest.mark.parametrize("share", [1.0, 0.7])
def test_a_change_the_drive_shows_too_is_not_the_sensor(share: float) -> None:
    """The joint's torque itself is off (in both channels, or in the drive by 70 % of it, the
    rest taken by another effect): the gain stands in for it; the constant tare is not
    compared (the drive has none)."""
    family = _OneJoint(cause_in_drive=share)
    check = channel_check(family, _fitted(family), "gain", np.arange(N))
    assert check is not None and [m[:2] for m in check.mirrored] == [("tau_J1", "tau_J_d1")]
    assert check.mirrored[0][2] == pytest.approx(share, abs=0.05)
    assert check.mirrored[0][2] >= MIRROR_SHARE
    assert "tau_J_d1 holds" in check.reasons()[0] and "stands in" in check.reasons()[0]


def test_no_siblings_no_mirror() -> None:
    family = _OneJoint(cause_in_drive=1.0)
    family.sibling_channels = None  # type: ignore[assignment]
    check = channel_check(family, _fitted(family), "gain", np.arange(N))
    assert check is not None and check.mirrored == ()
