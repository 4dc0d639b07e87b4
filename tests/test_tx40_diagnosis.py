"""A real Stäubli TX40 (../shared/realdata/staubli_tx40, FIGAROH's identification run) diagnosed
against its CAD URDF as a user would: imported with docs/examples/tx40_import.yaml, trained on
0.1-6 s, held out on 6-7.5 s (checks/tx40_table.py). Measured on this code (docs/diagnosis.md,
"A real Stäubli TX40"): the selected model's viscous friction within 4 % of the published OLS
values on every joint, Coulomb within 6 % on joints 1-5 (13 % on joint 6), the coupled motor's
fvm6 / fsm6 within 2 % / 11 %; Ia1 and Ia2 held (grouped with the link inertias); held-out RMS
CAD 26.2 / 18.9 / 9.6 / 5.8 / 2.9 / 3.9 N m -> 1.74 / 1.76 / 1.03 / 0.64 / 1.11 / 0.66, the
published model 2.05 / 1.64 / 1.76 / 0.79 / 0.96 / 0.74 on the same windows."""

from __future__ import annotations

import pytest
from tx40_support import TX40, import_tx40

from serpar.checks.tx40_table import tx40_table

pytestmark = [pytest.mark.skipif(not TX40.is_dir(), reason="../shared/realdata/staubli_tx40 "
                                 "not present"), pytest.mark.slow]


@pytest.fixture(scope="module")
def table(tmp_path_factory: pytest.TempPathFactory) -> dict:
    out = tmp_path_factory.mktemp("tx40") / "rec"
    import_tx40(out)
    return tx40_table(out, TX40)


def test_the_drive_friction_is_the_published_one(table: dict) -> None:
    fitted, pub = table["values"]["joint_friction"], table["published"]
    for j in range(1, 7):
        assert abs(fitted[f"Fv{j}"] / pub[f"fv{j}"] - 1) < 0.2, (j, fitted[f"Fv{j}"])
    for j in range(1, 6):
        assert abs(fitted[f"Fc{j}"] / pub[f"fs{j}"] - 1) < 0.2, (j, fitted[f"Fc{j}"])
    coupled = table["values"]["coupled_pair"]
    for name in ("fvm6", "fsm6"):
        assert abs(coupled[name] / pub[name] - 1) < 0.2, (name, coupled[name])


def test_rotor_inertias_grouped_with_the_links_are_named_not_fitted(table: dict) -> None:
    assert {"Ia1", "Ia2"} <= set(table["held"])
    assert any("Ia1, Ia2 cannot be identified" in n for n in table["notes"])


def test_the_selected_model_predicts_held_out_torque_as_well_as_the_published_one(table: dict
                                                                                   ) -> None:
    for cad, fitted, pub in zip(table["rms_nominal"], table["rms_fitted"],
                                table["rms_published"], strict=True):
        assert fitted < cad / 2.5 and fitted < 1.25 * pub, (cad, fitted, pub)
