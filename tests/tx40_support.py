"""The real Stäubli TX40 run (../shared/realdata/staubli_tx40) imported as docs/examples/
tx40_import.yaml documents it, for the tests that read it."""

from __future__ import annotations

from pathlib import Path

from serpar.cli.entry import main

TX40 = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "staubli_tx40"
DOCS = Path(__file__).resolve().parents[1] / "docs" / "examples"


def import_tx40(out: Path) -> Path:
    """The documented import command into ``out``; the recording folder."""
    assert main(["import", str(TX40 / "pos_read_data.csv"), str(TX40 / "curr_data.csv"),
                 "--spec", str(DOCS / "tx40_import.yaml"), "--sigma", "q2=9e-6,q3=6.4e-6",
                 "--out", str(out)]) == 0
    return out
