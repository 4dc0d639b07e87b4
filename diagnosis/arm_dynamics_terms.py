"""Everything the arm-dynamics residual needs, computed once per recording.

Two channels per joint, both "measured minus nominal model", in N m, one value per row:

* ``link`` = tau_J - (M_link q̈ + c + g): the link-side torque sensor against the rigid-body
  model. Sees payload, link inertia, encoder offsets and the torque sensor's own gain/offset;
  blind to anything inside the drive (friction, latency), which acts before the sensor.
* ``drive`` = tau_J_d - (M_link q̈ + c + g + armature q̈ + damping q̇): the command against
  what the drive must deliver. Sees payload, link inertia, encoder offsets, joint friction and
  actuation latency; blind to the torque sensor.

The two channels' different blind spots are what tell a torque-sensor gain from a payload, or
friction from a latency, when each alone fits one channel.

Noise of a row (the whitening), propagated from the recording's own noise model through the
window: the torque sensor's white noise (link) or the drive's torque ripple (drive) times the
window's noise gain, plus the encoder quantisation differentiated twice and multiplied by
the model's inertia (both channels): var_j = (gain·sigma_j)^2 + sum_m M_jm^2 (g_a·sigma_q,m)^2.
The inertia is the model's: an effect that adds inertia (payload, link mass) adds its
share, since the acceleration noise reaches the residual through the *true* inertia (a 1.4 kg
payload otherwise leaves a held-out RMS of 1.14 where the noise gives 1). Checked against
effect-free twins in tests/test_diagnosis_arm_dynamics.py.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import BSpline

from serpar.diagnosis.arm_dynamics_payload import load_torque
from serpar.diagnosis.arm_dynamics_signals import (
    MAX_LATENCY_S,
    ArmSeries,
    Rows,
    SmoothingConfig,
    full_rate_derivatives,
    noise_gains,
    windowed_spline,
)
from serpar.sim.rigid_arm import ArmDynamics, DynamicsSeries

Vec = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Terms:
    """Per-row quantities (rows x n joints unless noted)."""

    rows: Rows
    time: Vec
    """[s] at each row (window centre), shape (rows,)."""
    link: Vec
    drive: Vec
    sigma_link: Vec
    sigma_drive: Vec
    """Row noise of the nominal model (see :func:`row_sigma`)."""
    measurement_var: Vec
    """(link, drive) white-noise variance of a row per joint, 2 x n [N^2 m^2]."""
    acc_var: Vec
    """Variance of a row's acceleration from encoder quantisation, per joint [rad^2/s^4]."""
    mass_link: Vec
    mass_full: Vec
    """Nominal inertia at each row (rows x n x n): link side, and with the rotors."""
    q: Vec
    dq: Vec
    ddq: Vec
    """Windowed state at each row (the state effects on the drive channel are evaluated at)."""
    q_link: Vec
    dq_link: Vec
    ddq_link: Vec
    """The same, half a sample earlier: when the period-mean torque sensor reads."""
    a_full: Vec
    """Full-rate acceleration (second difference), samples x n."""
    q_full: Vec
    """The recorded angles (samples x n)."""
    tau_link_model: Vec
    """Windowed nominal link torque (period-mean timing), the torque-sensor gain's regressor."""
    tau_full_model: Vec
    """Windowed nominal drive torque (what the command should be)."""
    gravity: Vec
    """g(q) at each row: where the gravity load is high (the "where" table)."""
    dq_full: Vec
    """Full-rate velocity (samples x n), for friction regressors windowed per row."""
    command: BSpline
    """The windowed command mean as a cubic spline over (fractional) sample index: the
    latency effect reads it a delay earlier."""
    rate: float
    has_command: bool = True
    """False: the recording has no drive channel; only the link channel (tau_J) is compared."""
    has_link: bool = True
    """False: the recording has no link-side torque sensors (tau_J); only the drive channel."""
    drive_measured: bool = False
    """The drive channel is a measured drive torque (tau_drive), not the command (tau_J_d)."""

    @property
    def n(self) -> int:
        return int(self.q.shape[1])


def compute_terms(series: ArmSeries, cfg: SmoothingConfig | None = None,
                  dynamics: ArmDynamics | None = None) -> Terms:
    """Channels, row noise and the state at every row, from the nominal model (or `dynamics`)."""
    cfg = cfg or SmoothingConfig()
    dyn = dynamics or ArmDynamics()
    rows = Rows.of(len(series.time), cfg, series.breaks,
                   int(np.ceil(MAX_LATENCY_S * series.rate)))
    v, a = full_rate_derivatives(series.q, series.rate)
    model = dyn.series(series.q, v, a)  # every sample: the model is linear in the raw q̈
    if series.load is not None:  # the load the controller was told of is nominal, not missing
        known = load_torque(series.q, v, a, series.load)
        model = DynamicsSeries(model.link + known, model.full + known)
    # no link-side sensors: a link channel of zeros that nothing reads
    tau_j = series.tau_J if series.tau_J is not None else model.link
    link = rows.at(tau_j) - rows.link_at(model.link)
    if series.tau_J_d is None:  # no command: a drive channel of zeros that nothing reads
        cmd_mean = model.full
    elif series.drive_measured:  # a measured drive torque is the torque at t_k, not held
        cmd_mean = series.tau_J_d
    else:
        cmd_mean = np.empty_like(series.tau_J_d)  # continuous mean of the held command at t_k
        cmd_mean[1:] = 0.5 * (series.tau_J_d[1:] + series.tau_J_d[:-1])
        cmd_mean[0] = series.tau_J_d[0]
    drive = rows.at(cmd_mean - model.full)
    q_r, dq_r, ddq_r = rows.at(series.q), rows.at(v), rows.at(a)
    m_link, m_full = dyn.mass_link_and_full(q_r)
    g_link, g_cmd, g_acc = noise_gains(rows.kernel, series.rate)
    acc_var = (g_acc * series.sigma_q) ** 2
    if series.drive_measured:
        g_cmd = g_link
    sigma_tau = np.nan_to_num(series.sigma_tau, nan=1.0)  # no tau_J: nothing reads its sigma
    measurement_var = np.vstack([(g_link * sigma_tau) ** 2, (g_cmd * series.sigma_cmd) ** 2])
    sigma_link, sigma_drive = row_sigma(measurement_var, acc_var, m_link, m_full)
    spline = windowed_spline(rows, cmd_mean)  # the windowed command, between samples too
    return Terms(rows=rows, time=series.time[rows.centre], link=link, drive=drive,
                 sigma_link=sigma_link, sigma_drive=sigma_drive, measurement_var=measurement_var,
                 acc_var=acc_var, mass_link=m_link, mass_full=m_full, q=q_r, dq=dq_r, ddq=ddq_r,
                 q_link=rows.link_at(series.q), dq_link=rows.link_at(v),
                 ddq_link=rows.link_at(a), a_full=a,
                 q_full=series.q, tau_link_model=rows.link_at(model.link),
                 tau_full_model=rows.at(model.full), gravity=dyn.gravity(q_r), dq_full=v,
                 command=spline, rate=series.rate, has_command=series.tau_J_d is not None,
                 has_link=series.tau_J is not None, drive_measured=series.drive_measured)


def row_sigma(measurement_var: Vec, acc_var: Vec, mass_link: Vec, mass_full: Vec
              ) -> tuple[Vec, Vec]:
    """(link, drive) noise sigma of rows: the measured torque's white noise through the window,
    plus the encoder quantisation differentiated twice and carried by the inertia."""
    link = measurement_var[0] + np.einsum("rjm,m->rj", mass_link**2, acc_var)
    drive = measurement_var[1] + np.einsum("rjm,m->rj", mass_full**2, acc_var)
    return np.sqrt(link), np.sqrt(drive)
