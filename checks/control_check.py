"""``serpar control-check``: the seed's controller figures, each beside the paper's value."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from serpar.checks.arm_checks import force_position_descent, path_accuracy, press
from serpar.checks.stewart_checks import commanded_vs_simulated, ik_fk_round_trip
from serpar.controllers.arm_controller import ControlLaw
from serpar.sim.stewart import StewartConfig

PAPER = {
    "path": "max deviation X/Y/Z < 0.4 mm (Fig. 3)",
    "descent": "final error X/Y/Z < 0.2 mm (Fig. 5)",
    "press": "direct force-position chosen over impedance (no figures given)",
    "round_trip": "<= 1e-9 m (issue bound; the paper gives none)",
    "tracking": "<= 1 um, <= 1e-4 deg (issue bound; perfect geometry)",
}
STAGES = ("path", "descent", "press", "round_trip", "tracking")


@dataclass(frozen=True)
class ControlCheckReport:
    noise: bool
    results: dict

    def passed(self) -> dict[str, bool]:
        r = self.results
        out = {}
        if "path" in r:
            out["path"] = max(r["path"]["max_deviation_mm"]) < 0.4
        if "descent" in r:
            out["descent"] = max(r["descent"]["final_error_mm"]) < 0.2
        if "round_trip" in r:
            out["round_trip"] = r["round_trip"]["max_position_error_m"] <= 1e-9
        if "tracking" in r:
            out["tracking"] = (r["tracking"]["max_position_error_m"] <= 1e-6
                               and r["tracking"]["max_rotation_error_deg"] <= 1e-4)
        return out

    def as_dict(self) -> dict:
        return {"noise": self.noise, "paper": PAPER, "results": self.results,
                "passed": self.passed()}


def run_control_check(noise: bool = True, seed: int = 0, stages: tuple[str, ...] = STAGES,
                      progress: Callable[[str], None] | None = None) -> ControlCheckReport:
    """Run the selected stages (all by default); noise switches the arm's sensor model."""
    results: dict = {}
    for stage in stages:
        if progress:
            progress(stage)
        if stage == "path":
            results[stage] = path_accuracy(noise, seed=seed).as_dict()
        elif stage == "descent":
            results[stage] = force_position_descent(noise, seed=seed).as_dict()
        elif stage == "press":
            results[stage] = {law.value: press(law, noise, seed=seed).as_dict()
                              for law in (ControlLaw.IMPEDANCE, ControlLaw.FORCE_POSITION)}
        elif stage == "round_trip":
            results[stage] = ik_fk_round_trip(StewartConfig().geometry(), 1000, seed).as_dict()
        elif stage == "tracking":
            results[stage] = commanded_vs_simulated().as_dict()
    return ControlCheckReport(noise, results)
