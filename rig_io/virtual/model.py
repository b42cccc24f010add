"""Physical parameters of the virtual rigs and the discretised tendon path built from them."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from rig_io.virtual import physics as ph
from rig_io.virtual.effects import EffectStrengths

RIG_NAMES = ("tsm-bench", "bending-joint")


@dataclass(frozen=True)
class TSMParams:
    """The tsm-bench of seed 001 (Tables 2.1 and 2.3, chapter 3) plus calibrated friction.

    Lengths in mm, forces in N. ``sheath_ea_n`` (the flat-wire coil's effective compression
    stiffness, fittings included) and the friction terms are the calibrated ones: they set the
    loop sizes to the magnitudes of seed 001 (output lag up to ~1.5-2 mm at 90 deg, 30 mm).
    """

    sheath_length_mm: float = 1100.0
    tendon_length_mm: float = 1400.0
    tendon_diameter_mm: float = 0.381
    sheath_inner_diameter_mm: float = 0.460
    #: 7x19 tungsten, 0.3 % elongation at the 235 N break load (Table 2.3): EA = 78.3 kN.
    tendon_ea_n: float = 235.0 / 0.003
    #: Flat-wire coil sheath: compression stiffness at zero load (fittings included) and the
    #: tension over which it stiffens as the turn gaps close.
    sheath_ea_n: float = 450.0
    sheath_stiffening_n: float = 1.0
    mu: float = 0.2
    #: Turning of the nominally straight lead-in/out (sag of the suspended sheath, fittings),
    #: rad per metre of sheath.
    straight_turn_rad_per_m: float = 0.5
    #: Bending-stiffness contact: normal force per mm of arc = k / r^2 (EI over a contact length).
    bend_contact_n_mm: float = 10.0
    #: The tendon wedges into the coil's turn gaps on the inside of a bend, the more so the
    #: further it has wrapped (the gaps close progressively along the bend): the capstan normal
    #: force on the arc is multiplied by (1 + (rho / r) (wrap so far / wedge_wrap)^2).
    #: Calibrated so that the radius matters at large curve angles and hardly at small ones
    #: (seed 001 section 3.2.3).
    coil_wedge_mm: float = 60.0
    wedge_wrap_deg: float = 90.0
    lost_motion_tension_n: float = 1.0
    pretension_n: float = 4.0
    follower_rate_n_mm: float = 0.0
    follower_friction_n: float = 0.15
    #: Breakaway friction of the follower's guide (stick-slip at every reversal).
    follower_breakaway_n: float = 0.45
    #: State at t=0: "released" (the carriage was homed by moving back, the usual case),
    #: "pulled", or "neutral" (uniform pretension).
    initial_state: str = "released"
    n_lead_in: int = 14
    n_arc: int = 22
    n_lead_out: int = 14
    #: Friction varies with the sliding distance (strand lay of the 7x19 cable, coil pitch):
    #: relative RMS of the modulation, and the wavelength range of its components (mm).
    friction_texture: float = 0.12
    #: Frictional memory of the sheath contact (s): the speed-dependent part of the friction
    #: follows the sliding speed through this lag (friction lags velocity changes in
    #: lubricated contacts, Hess & Soom 1990), not the carriage's lurches inside a servo tick.
    friction_memory_s: float = 0.02
    texture_wavelength_mm: tuple[float, float] = (0.7, 4.0)
    #: Vibration of the follower carriage (RMS mm, correlation time s): the rig's noise floor.
    follower_vibration_mm: float = 0.04
    follower_vibration_tau_s: float = 0.2
    servo_tau_s: float = 0.006
    servo_vmax_mm_s: float = 40.0
    physics_dt_s: float = 0.001
    control_dt_s: float = 0.01
    #: bending joint (seed 000 eq. 1-9): section length, tendon offset diameter D, rest angle,
    #: backbone stiffness (N mm / rad) and the motor pulley radius for degree commands.
    section_length_mm: float = 30.0
    section_diameter_mm: float = 8.0
    rest_angle_deg: float = 0.0
    backbone_stiffness_nmm_rad: float = 12.0
    bending_pretension_n: float = 1.5
    pulley_radius_mm: float = 5.0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class Chain:
    """Arrays the numba kernels work on (segments, nodes, scalar parameter vector)."""

    theta: np.ndarray
    cont: np.ndarray
    coef: np.ndarray
    p: np.ndarray
    tens0: np.ndarray
    arc_nodes: slice = field(default_factory=lambda: slice(0, 0))

    @property
    def n_segments(self) -> int:
        return int(self.coef.shape[0])


def params_with(overrides: dict[str, Any] | None) -> TSMParams:
    """Default parameters with ``overrides`` (unknown names raise ``ValueError``)."""
    base = TSMParams()
    if not overrides:
        return base
    known = set(base.to_dict())
    bad = sorted(set(overrides) - known)
    if bad:
        raise ValueError(f"unknown rig parameter(s) {bad}; known: {sorted(known)}")
    return replace(base, **overrides)


def _arc(curve_angle_deg: float, radius_mm: float, params: TSMParams
         ) -> tuple[float, float, float, float]:
    """(angle in rad, radius, arc length, straight length) of a checked sheath shape."""
    phi = math.radians(float(curve_angle_deg))
    r = float(radius_mm)
    if not 0.0 <= phi <= math.pi:
        raise ValueError(f"curve_angle_deg must be in [0, 180], got {curve_angle_deg}")
    if r <= 0.0:
        raise ValueError(f"radius_mm must be positive, got {radius_mm}")
    arc_len = r * phi
    straight = params.sheath_length_mm - arc_len
    if straight <= 0.0:
        raise ValueError(f"arc of {arc_len:.1f} mm does not fit in the "
                         f"{params.sheath_length_mm} mm sheath")
    return phi, r, arc_len, straight


def build_chain(*, rig: str, curve_angle_deg: float, radius_mm: float, params: TSMParams,
                effects: EffectStrengths) -> Chain:
    """Discretise lead-in / arc / lead-out and set the kernels' parameter vector."""
    if rig not in RIG_NAMES:
        raise ValueError(f"unknown rig {rig!r}; expected one of {RIG_NAMES}")
    phi, r, arc_len, straight = _arc(curve_angle_deg, radius_mm, params)
    free = params.tendon_length_mm - params.sheath_length_mm
    l_in = l_out = 0.5 * straight
    n_in, n_arc, n_out = params.n_lead_in, params.n_arc, params.n_lead_out
    # Segments: free input end, sheath elements, free output end.
    ds = np.concatenate([[0.5 * free], np.full(n_in, l_in / n_in), np.full(n_arc, arc_len / n_arc),
                         np.full(n_out, l_out / n_out), [0.5 * free]])
    in_sheath = np.concatenate([[0.0], np.ones(n_in + n_arc + n_out), [0.0]])
    m = ds.shape[0]
    ea_t = params.tendon_ea_n
    ea_s = params.sheath_ea_n
    # The coil sheath only carries compression where the tendon runs inside it.
    comp_tendon = ds / ea_t
    comp_sheath = in_sheath * ds / ea_s
    # Node j sits at the start of segment j (j = 1..m-1); node 0 is the input end.
    theta = np.zeros(m)
    cont = np.zeros(m)
    kappa_straight = params.straight_turn_rad_per_m / 1000.0
    wrap_ref = math.radians(params.wedge_wrap_deg)
    lm = np.zeros(m)
    clearance = 0.5 * (params.sheath_inner_diameter_mm - params.tendon_diameter_mm)
    for j in range(1, m):
        seg = j  # node j spreads the turning of segment j (sheath segments 1..m-2)
        if 1 <= seg <= n_in or n_in + n_arc < seg <= n_in + n_arc + n_out:
            theta[j] = kappa_straight * ds[seg]
        elif n_in < seg <= n_in + n_arc:
            wrapped = (seg - n_in - 0.5) * phi / n_arc
            theta[j] = (phi / n_arc) * (1.0 + params.coil_wedge_mm / r * (wrapped / wrap_ref) ** 2)
            cont[j] = params.bend_contact_n_mm / r**2 * ds[seg]
            lm[seg] = clearance * (phi / n_arc)
    # The last node (before the free output end) is the sheath exit: no turning there.
    f_rest = _rest_tension(rig, params)
    tens0 = np.full(m, f_rest)
    if params.initial_state in ("released", "pulled"):
        sgn = -1.0 if params.initial_state == "released" else 1.0
        ph._backward(f_rest + sgn * params.follower_friction_n, sgn, params.mu, tens0, theta,
                     cont)
    elif params.initial_state != "neutral":
        raise ValueError(f"initial_state must be 'released', 'pulled' or 'neutral', got "
                         f"{params.initial_state!r}")
    p = _kernel_parameters(rig, params, effects)
    elong = effects.elongation_coeff() * ds
    coef = np.ascontiguousarray(np.stack([comp_tendon, lm, elong, comp_sheath], axis=1))
    return Chain(theta=theta, cont=cont, coef=coef, p=p, tens0=tens0,
                 arc_nodes=slice(n_in + 1, n_in + n_arc + 1))


def _kernel_parameters(rig: str, params: TSMParams, effects: EffectStrengths) -> np.ndarray:
    """The physics kernels' parameter vector (indices ``ph.P_*``)."""
    p = np.zeros(ph.N_P)
    p[ph.P_MU] = params.mu
    p[ph.P_F0] = _rest_tension(rig, params)
    p[ph.P_KF] = params.follower_rate_n_mm if rig == "tsm-bench" else bending_rate(params)
    p[ph.P_FF] = params.follower_friction_n
    p[ph.P_FS] = params.follower_breakaway_n
    p[ph.P_TREF] = _rest_tension(rig, params)
    p[ph.P_TC] = params.lost_motion_tension_n
    # Stops are relative to the start position; the rig core shifts them (see rig._Core).
    p[ph.P_STOP] = effects.saturation_stop_mm()
    p[ph.P_STOP_LO] = -effects.saturation_stop_mm()
    p[ph.P_ASYM] = effects.asymmetry_fraction()
    p[ph.P_RATE] = effects.rate_gain()
    p[ph.P_V0] = effects.rate_v0_mm_s()
    p[ph.P_TF] = params.friction_memory_s
    p[ph.P_PLAY] = effects.dead_zone_mm()
    p[ph.P_TAU] = params.servo_tau_s
    p[ph.P_VMAX] = params.servo_vmax_mm_s
    p[ph.P_DT] = params.physics_dt_s
    p[ph.P_TS] = params.sheath_stiffening_n
    return p


def _rest_tension(rig: str, params: TSMParams) -> float:
    return params.pretension_n if rig == "tsm-bench" else params.bending_pretension_n


def bending_rate(params: TSMParams) -> float:
    """Follower spring rate of a bending section: tension T D/2 = K alpha, alpha = 2 dl / D."""
    d = params.section_diameter_mm
    return 4.0 * params.backbone_stiffness_nmm_rad / (d * d)


def tip_angle_deg(distal_pull_mm: np.ndarray, params: TSMParams) -> np.ndarray:
    """Seed 000 eq. 6-7: alpha = 2 dl / D (+ the rest angle)."""
    return params.rest_angle_deg + np.degrees(2.0 * distal_pull_mm / params.section_diameter_mm)


def tip_position_mm(alpha_deg: np.ndarray, params: TSMParams, beta_rad: float = 0.0,
                    xi_mm: float = 0.0) -> np.ndarray:
    """Seed 000 eq. 1-3: tip position of the constant-curvature section, shape (n, 3)."""
    a = np.radians(np.asarray(alpha_deg, dtype=float))
    lf = params.section_length_mm
    safe = np.where(np.abs(a) < 1e-9, 1e-9, a)
    radial = lf / safe * (1.0 - np.cos(safe))
    axial = lf / safe * np.sin(safe)
    return np.stack([-math.sin(beta_rad) * radial, math.cos(beta_rad) * radial,
                     axial + xi_mm], axis=1)
