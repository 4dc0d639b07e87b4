"""A description of a compiled scene: what ``serpar info`` prints."""

from __future__ import annotations

import mujoco
import numpy as np

from serpar.sim.scene import Scene


def _names(model: mujoco.MjModel, obj: mujoco.mjtObj, count: int) -> list[str]:
    return [mujoco.mj_id2name(model, obj, i) or f"<{i}>" for i in range(count)]


def _camera_info(model: mujoco.MjModel, i: int) -> dict:
    width, height = (int(v) for v in model.cam_resolution[i])
    fx_m, fy_m = (float(v) for v in model.cam_intrinsic[i][:2])
    sx, sy = (float(v) for v in model.cam_sensorsize[i])
    return {
        "name": model.camera(i).name,
        "resolution": [width, height],
        "focal_length_mm": round(fx_m * 1e3, 4),
        "focal_px": [round(fx_m / sx * width, 2), round(fy_m / sy * height, 2)],
        "pixel_um": round(sx / width * 1e6, 3),
        "fovy_deg": round(float(model.cam_fovy[i]), 3),
    }


def scene_info(scene: Scene) -> dict:
    """Bodies, DoF, actuators, sensors, cameras, timestep and drawn diameters of `scene`."""
    m, cfg, dia = scene.model, scene.config, scene.diameters
    holes_um = np.array(dia.holes) * 1e6
    journals_um = np.array(dia.journals) * 1e6
    # Clearance of every hole with every conductor: what the task may pair up.
    clear = (holes_um[:, None] - journals_um[None, :]) if len(journals_um) else np.zeros((0, 0))
    bore = cfg.baseplate.bore(max(dia.holes))  # widest hole + thinnest journal: worst roundness
    return {
        "seed": cfg.seed,
        "timestep_s": m.opt.timestep,
        "counts": {"bodies": m.nbody, "geoms": m.ngeom, "nq": m.nq, "dof": m.nv, "actuators": m.nu,
                   "sensors": m.nsensor, "cameras": m.ncam, "equality_constraints": m.neq},
        "actuators": _names(m, mujoco.mjtObj.mjOBJ_ACTUATOR, m.nu),
        "sensors": _names(m, mujoco.mjtObj.mjOBJ_SENSOR, m.nsensor),
        "cameras": [_camera_info(m, i) for i in range(m.ncam)],
        "holes_um": [round(float(v), 3) for v in holes_um],
        "journals_um": [round(float(v), 3) for v in journals_um],
        "bodies_um": [round(float(v) * 1e6, 3) for v in dia.bodies],
        "clearance_um": {
            "min": round(float(clear.min()), 3) if clear.size else None,
            "max": round(float(clear.max()), 3) if clear.size else None,
            "mean": round(float(clear.mean()), 3) if clear.size else None,
        },
        "bore_facets": cfg.baseplate.n_facets,
        "bore_roundness_um_worst": round(bore.roundness_error(min(dia.journals, default=1.694e-3)) * 1e6, 4),
        "chamfer_mm": cfg.baseplate.chamfer * 1e3,
        "tolerance_distribution": cfg.tolerance_distribution,
    }
