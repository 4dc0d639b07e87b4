import numpy as np
import pytest

from serpar.errors import ConfigError
from serpar.sim.tolerances import HOLE_H7, JOURNAL_H6, draw_diameters


def test_draws_stay_in_band_and_span_the_fit():
    d = draw_diameters(seed=7, n_holes=2000, n_conductors=2000)
    holes, journals = np.array(d.holes), np.array(d.journals)
    assert holes.min() >= HOLE_H7.min and holes.max() <= HOLE_H7.max
    assert journals.min() >= JOURNAL_H6.min and journals.max() <= JOURNAL_H6.max
    clearance = holes - journals
    assert clearance.min() >= 0.0 and clearance.max() <= 16e-6
    # Uniform draws cover most of the 0-16 um range (seed 000: T_f = 0.016 mm).
    assert clearance.min() < 2e-6 and clearance.max() > 14e-6


def test_same_seed_same_parts_and_normal_draws_clip():
    assert draw_diameters(3, 36, 36) == draw_diameters(3, 36, 36)
    assert draw_diameters(3, 36, 36) != draw_diameters(4, 36, 36)
    n = draw_diameters(1, 5000, 10, "normal")
    assert min(n.holes) >= HOLE_H7.min and max(n.holes) <= HOLE_H7.max
    assert abs(np.mean(n.holes) - 1.705e-3) < 0.2e-6


def test_bad_seed_and_distribution():
    with pytest.raises(ConfigError, match="integer"):
        draw_diameters("1", 1, 1)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="valid: uniform, normal"):
        draw_diameters(1, 1, 1, "gauss")  # type: ignore[arg-type]
