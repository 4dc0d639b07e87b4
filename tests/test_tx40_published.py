"""checks/tx40_published.py: the Staubli TX40's published identification (FIGAROH,
../shared/realdata/staubli_tx40/published/TX40_bp_5.csv) against its CAD model on the real
recording, imported with docs/examples/tx40_import.yaml."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from tx40_support import TX40, import_tx40

from serpar.checks.tx40_published import (
    FRAME_TOL,
    PUBLISHED,
    base_matrix,
    compare,
    parse_expression,
    published_model,
    read_published,
    sane,
)
from serpar.errors import ConfigError

pytestmark = pytest.mark.skipif(not TX40.is_dir(), reason="../shared/realdata/staubli_tx40 not present")

HELD_OUT_BOUND = (3.0, 3.1, 2.0, 1.0, 1.5, 1.0)
"""[N m] per joint, on 6-7.5 s; measured (OLS values, 100 Hz filter, 1e-3 rad/s dead band):
published 2.36, 2.40, 1.50, 0.76, 1.16, 0.75 against CAD 25.8, 19.0, 9.7, 5.9, 3.0, 3.7."""


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("tx40") / "rec"
    import_tx40(out)
    return out


def test_every_published_row_parses() -> None:
    rows = read_published(TX40 / PUBLISHED)
    assert len(rows) == 60
    for row in rows:  # every name written in the row is a term, with its sign
        names = re.findall(r"[A-Za-z]+\d", row.name)
        assert sorted(row.terms) == sorted(names), row.name
    terms = {r.name: r.terms for r in rows}
    assert terms["my3 - 1.0*mz4 - 0.225*m4 - 0.225*m5 - 0.225*m6"] == {
        "my3": 1.0, "mz4": -1.0, "m4": -0.225, "m5": -0.225, "m6": -0.225}
    b, inertial, grouped = base_matrix(rows)
    assert b.shape == (36, 60) and np.linalg.matrix_rank(b) == 36 and grouped == ("Ia1", "Ia2")
    model = published_model(rows)
    assert len(model.drive) == 24  # fv, fs, off per joint, Ia3..Ia5, Iam6, fvm6, fsm6
    assert np.allclose(b @ model.phi, [r.ols for r in inertial])
    for bad in ("Izz1 Iyy2", "q1", "Izz1 + 2*", "Izz1 + 1.0*ly3"):
        with pytest.raises(ConfigError):
            parse_expression(bad)


def test_published_model_beats_cad_on_held_out_span(recording: Path) -> None:
    """Measured (0.1-6 s, inside the authors' 0.1-7.5 s fit): published 2.53, 2.95, 1.48,
    0.69, 1.21, 0.74 against CAD 31.7, 22.1, 12.7, 6.3, 10.0, 5.8 N m; on 6-7.5 s see
    :data:`HELD_OUT_BOUND`. Joint 6 is 3.0 N m on 0.1-6 s without FIGAROH's coupled share on
    joint 6 (Iam6 ddq5 + fvm6 dq5 + fsm6 sign(dq5 + dq6))."""
    c = compare(recording, TX40)
    assert c.frame_check["regressor"] < FRAME_TOL and c.frame_check["grouping"] < FRAME_TOL
    fit, held = c.spans
    assert (fit.samples, held.samples) == (5900, 1500)
    assert sane(c)
    for j in range(6):
        assert held.published[j] < held.cad[j], (j + 1, held)
        assert held.published[j] < HELD_OUT_BOUND[j], (j + 1, held.published)
