"""The hybrid model of the rolling wheel (paper Sec. III), written once.

Hybrid state x = (xi1, xi2, q, Delta, delta, eta):

* xi1 [rad]      unwrapped wheel angle (grows while rolling forward),
* xi2 [rad/s]    wheel speed,
* q   {0, 1}     HV on the actuator of interest,
* Delta [rad]    activation-angle down counter,
* delta [rad]    deactivation-angle down counter,
* eta [-]        *unwrapped* sector index of the actuator of interest (actuator = eta mod 16).

Input u = (n_a, phi_a, phi_d): target actuator 0..15 and the contact angles [rad] at which
it switches on and off.  Positive angles accelerate, negative angles brake (Sec. III-D).

The functions take plain floats and a parameter vector ``pv`` (see :mod:`.layout` and
:func:`param_vector`); numba compiles them (see :mod:`.jit`).  The plant, the MPC predictor
and the identification all integrate these same functions through :mod:`.integrator`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.jit import jit, jit_inline
from hasel_wheel_sim.params import FieldSpec, ParameterError, WheelParams, check_value

#: Angle between adjacent actuator pads [rad].
SECTOR = math.pi / 8.0
#: Number of actuators on the wheel.
N_ACTUATORS = 16
#: Below this |contact angle| [rad] the force law is taken as 0 (its limit at 0).
TINY_ANGLE = 1e-12


#: Scalar fields of :class:`Extensions`: unit and allowed range (phases as atan2 gives them).
EXTENSION_FIELDS: dict[str, FieldSpec] = {
    "com_torque": FieldSpec("N*m", 0.0, 1.0, True, True, doc="off-centre mass: m_offset * g * e"),
    "com_phase": FieldSpec("rad", -math.pi, math.pi, True, True, doc="angle of the offset"),
    "platform_torque": FieldSpec("N*m", 0.0, 1.0, True, True, doc="platform disturbance amplitude"),
    "platform_phase": FieldSpec("rad", -math.pi, math.pi, True, True, doc="pivot angle of its peak"),
    "viscous": FieldSpec("N*m*s/rad", 0.0, 1.0, True, True, doc="drag torque per speed"),
    "rise_time": FieldSpec("s", 0.0, 1.0, True, True, doc="actuator force build-up; 0 = instant"),
    "retention_rate": FieldSpec("1/s", 0.0, 10.0, True, True, doc="force loss per s of HV time"),
    "retention_recovery": FieldSpec("s", 0.0, 1e6, False, True, doc="recovery time constant"),
    "angle_eccentricity": FieldSpec("rad", 0.0, 0.2, True, True,
                                    doc="first-harmonic error of the angle reading"),
    "angle_eccentricity_phase": FieldSpec("rad", -math.pi, math.pi, True, True,
                                          doc="wheel angle where the reading error peaks is pi/2 - phase"),
    "start_torque": FieldSpec("N*m", 0.0, 1.0, True, True,
                              doc="push of a pad switched on at a standing wheel; 0 = none"),
    "start_stroke": FieldSpec("rad", 0.0, 1.0, False, True,
                              doc="wheel travel over which that push falls to 0"),
    "start_speed": FieldSpec("rad/s", 0.0, 10.0, False, True,
                             doc="switch-on speed at and above which a pad does not push"),
}
#: Unit and allowed range of each of the 16 actuator gains.
GAIN_SPEC = FieldSpec("1", 0.0, 10.0, False, True, doc="per-actuator force gain")


@dataclass(frozen=True)
class Extensions:
    """Physical effects the paper's model lacks, as parameters of the model (all off by default).

    ``com_torque`` [N*m], ``com_phase`` [rad]: a COM offset from the geometric centre gives the
        axle torque -com_torque * sin(xi1 + com_phase) (com_torque = m_offset * g * e).
    ``platform_torque`` [N*m], ``platform_phase`` [rad]: a disturbance fixed to the platform,
        periodic in the pivot angle psi = (r/L) xi1 (eq. (8)): +platform_torque * sin(psi + phase).
    ``viscous`` [N*m*s/rad]: drag torque -viscous * xi2.
    ``rise_time`` [s]: the actuator force builds up as 1 - exp(-t_on / rise_time) after switch-on.
    ``retention_rate`` [1/s], ``retention_recovery`` [s]: charge retention.  Each actuator i
        accumulates Q_i with dQ_i/dt = q_i - Q_i / retention_recovery [s of HV time]; its force
        is scaled by exp(-retention_rate * Q_i).
    ``gains`` [1] x16: per-actuator force gain (fabrication spread).
    ``angle_eccentricity`` [rad], ``angle_eccentricity_phase`` [rad]: the angle sensor reads
        xi1 + angle_eccentricity * sin(xi1 + phase) (an encoder disc or magnet off the axle).
        Not a torque: the firmware switches the actuators when its *reading* reaches the
        switching angle, and every recorded angle is a reading (:func:`angle_reading`).
    ``start_torque`` [N*m], ``start_stroke`` [rad], ``start_speed`` [rad/s]: the push of a pad
        switched on at a standing or slow wheel (:func:`start_push`), what starts a wheel
        from rest (docs/model.md, "Start from rest").
    """

    com_torque: float = 0.0
    com_phase: float = 0.0
    platform_torque: float = 0.0
    platform_phase: float = 0.0
    viscous: float = 0.0
    rise_time: float = 0.0
    retention_rate: float = 0.0
    retention_recovery: float = 300.0
    angle_eccentricity: float = 0.0
    angle_eccentricity_phase: float = 0.0
    start_torque: float = 0.0
    start_stroke: float = 0.1
    start_speed: float = 0.5
    gains: tuple[float, ...] = field(default=(1.0,) * N_ACTUATORS)

    def __post_init__(self) -> None:
        """Range-check every field (:data:`EXTENSION_FIELDS`, :data:`GAIN_SPEC`), so that no
        value reaches the compiled core that it would turn into inf or nan; raises
        :class:`~hasel_wheel_sim.params.ParameterError` naming the field and its range."""
        for name, spec in EXTENSION_FIELDS.items():
            check_value(name, getattr(self, name), spec, "Extensions")
        if len(self.gains) != N_ACTUATORS:
            raise ParameterError(f"Extensions: field 'gains' has {len(self.gains)} entries; "
                                 f"expected {N_ACTUATORS} numbers in {GAIN_SPEC.describe()}")
        for i, g in enumerate(self.gains):
            check_value(f"gains[{i}]", g, GAIN_SPEC, "Extensions")


def param_vector(p: WheelParams, ext: Extensions | None = None) -> np.ndarray:
    """Pack parameters into the float64 vector the compiled core reads, shape (L.P_SIZE,)."""
    ext = ext or Extensions()
    pv = np.zeros(L.P_SIZE)
    pv[L.P_R] = p.r
    pv[L.P_SIGMA1] = p.sigma1
    pv[L.P_SIGMA2] = p.sigma2
    pv[L.P_SIGMA3] = p.sigma3
    pv[L.P_SIGMA4] = p.sigma4
    pv[L.P_INV_S5SQ] = 1.0 / p.sigma5**2
    pv[L.P_SIGMA6] = p.sigma6
    pv[L.P_BRAKE_GAIN] = p.brake_gain
    pv[L.P_FRICTION] = p.friction_torque
    pv[L.P_INV_INERTIA] = 1.0 / p.inertia
    pv[L.P_PIVOT_RATIO] = p.r / p.L
    pv[L.P_COM_TORQUE] = ext.com_torque
    pv[L.P_COM_PHASE] = ext.com_phase
    pv[L.P_PLATFORM_TORQUE] = ext.platform_torque
    pv[L.P_PLATFORM_PHASE] = ext.platform_phase
    pv[L.P_VISCOUS] = ext.viscous
    pv[L.P_RISE_TIME] = ext.rise_time
    pv[L.P_RET_RATE] = ext.retention_rate
    pv[L.P_RET_RECOVERY] = ext.retention_recovery
    pv[L.P_BAND_LO], pv[L.P_BAND_HI] = force_band(p)
    pv[L.P_GAINS:L.P_GAINS + N_ACTUATORS] = ext.gains
    # e sin(xi1 + phase) = e sin(phase) cos(xi1) + e cos(phase) sin(xi1)
    pv[L.P_READ_COS] = ext.angle_eccentricity * math.sin(ext.angle_eccentricity_phase)
    pv[L.P_READ_SIN] = ext.angle_eccentricity * math.cos(ext.angle_eccentricity_phase)
    pv[L.P_START_TORQUE] = ext.start_torque
    pv[L.P_START_STROKE] = ext.start_stroke
    pv[L.P_START_SPEED] = ext.start_speed
    return pv


def reading_param_vector(p: WheelParams, ext: Extensions | None = None) -> np.ndarray:
    """:func:`param_vector` (shape (L.P_SIZE,)) for a model that works on the angle readings
    themselves (the observer and the MPC): the sensor's eccentricity is left out
    (P_READ_* = 0), so their switching angles are readings, as the firmware's are.  What it
    does to the motion seen through the readings is neglected: an apparent acceleration of
    about -e xi2^2 sin(xi1 + phase) [rad/s^2] (0.08 rad/s^2 at 5 mrad and 4 rad/s), once
    per turn, which the observer's once-per-turn disturbance terms take up as it goes."""
    pv = param_vector(p, ext)
    pv[L.P_READ_COS] = pv[L.P_READ_SIN] = 0.0
    return pv


@jit_inline
def angle_reading(xi1: float, pv: np.ndarray) -> float:
    """What the angle sensor reads [rad] at the wheel angle xi1 [rad]:
    xi1 + P_READ_COS cos(xi1) + P_READ_SIN sin(xi1) (xi1 itself for an exact sensor)."""
    a = pv[L.P_READ_COS]
    b = pv[L.P_READ_SIN]
    if a == 0.0 and b == 0.0:
        return xi1
    return xi1 + a * math.cos(xi1) + b * math.sin(xi1)


@jit_inline
def angle_at_reading(m: float, pv: np.ndarray) -> float:
    """The wheel angle [rad] at which the sensor reads m [rad] (the inverse of
    :func:`angle_reading`).  The reading's slope 1 - a sin + b cos stays >= 1 - 0.2 for the
    amplitudes allowed (<= 0.2 rad), so it is increasing and Newton's iteration from m
    converges quadratically; 8 steps reach rounding."""
    a = pv[L.P_READ_COS]
    b = pv[L.P_READ_SIN]
    if a == 0.0 and b == 0.0:
        return m
    x = m
    for _ in range(8):
        c = math.cos(x)
        s = math.sin(x)
        f = x + a * c + b * s - m
        x -= f / (1.0 - a * s + b * c)
        if abs(f) < 1e-15:
            break
    return x


@jit_inline
def contact_at_switch_on(eta: float, phi_a: float, pv: np.ndarray) -> float:
    """The true contact angle [rad] at which an actuator commanded at phi_a [rad] switches on:
    where the sensor reads eta pi/8 + phi_a, less eta pi/8 (phi_a itself with an exact sensor).

    The force law's rise term (xi_c - phi_a) starts at 0 at switch-on only with this angle in
    it: the firmware switches on its reading, the pad's force grows with the true travel.
    With an exact sensor phi_a itself is returned, bit for bit (not base + phi_a - base)."""
    if pv[L.P_READ_COS] == 0.0 and pv[L.P_READ_SIN] == 0.0:
        return phi_a
    base = eta * SECTOR
    return angle_at_reading(base + phi_a, pv) - base


def angle_readings(xi1: np.ndarray, pv: np.ndarray) -> np.ndarray:
    """:func:`angle_reading` of an array of wheel angles xi1 (n,) [rad] -> (n,) [rad]."""
    a, b = float(pv[L.P_READ_COS]), float(pv[L.P_READ_SIN])
    if a == 0.0 and b == 0.0:
        return xi1
    return xi1 + a * np.cos(xi1) + b * np.sin(xi1)


#: The force law is taken as 0 where its bump is below exp(-BAND_EXPONENT) of its peak.
BAND_EXPONENT = 60.0


def force_band(p: WheelParams) -> tuple[float, float]:
    """|contact angle| interval [rad] outside which the force law is < e^-60 (1e-26) of its peak.

    The bump's exponent -s1 ln x - (ln x - s4)^2 / s5^2 is a parabola in ln x with its top at
    c = s4 - s1 s5^2 / 2, so it is 60 below the top where |ln x - c| = sqrt(60) |s5|.  A torque
    1e-26 times the peak one cannot change a double-precision sum with friction (~1e-2 N*m),
    so skipping the evaluation there changes no result; it only saves the log, exp and sin.
    """
    c = p.sigma4 - p.sigma1 * p.sigma5**2 / 2.0
    half = math.sqrt(BAND_EXPONENT) * abs(p.sigma5)
    return math.exp(c - half), math.exp(c + half)


@jit_inline
def force_law(xi_c: float, xi2: float, phi_a: float, pv: np.ndarray) -> float:
    """Actuation force F_a [N] of (43) for an actuator that is on (q = 1).

    Positive contact angles use (43) as published.  Negative contact angles are braking
    (Sec. III-D), which the paper does not model.  Our braking model mirrors the law about
    xi_c = 0 and scales it by ``brake_gain`` (identifiable from braking data):

        F(xi_c) = k * |xi_c|^-s1 / (s2 |xi2| + s3) * exp(-(ln|xi_c| - s4)^2 / s5^2)
                  * s6 * (xi_c - phi_a),          k = 1 (xi_c > 0), brake_gain (xi_c < 0).

    The rise term (xi_c - phi_a) is >= 0 while the actuator is on, because it switches on at
    xi_c = phi_a and xi_c grows as the wheel rolls.  Speed enters as |xi2| so the denominator
    stays positive if the wheel rolls backwards.
    """
    x = abs(xi_c)
    if x < TINY_ANGLE or x < pv[L.P_BAND_LO] or x > pv[L.P_BAND_HI]:
        return 0.0
    lx = math.log(x)
    dl = lx - pv[L.P_SIGMA4]
    bump = math.exp(-pv[L.P_SIGMA1] * lx - dl * dl * pv[L.P_INV_S5SQ])
    k = pv[L.P_BRAKE_GAIN] if xi_c < 0.0 else 1.0
    return k * bump * pv[L.P_SIGMA6] * (xi_c - phi_a) / (pv[L.P_SIGMA2] * abs(xi2) + pv[L.P_SIGMA3])


@jit_inline
def start_push(xi_c: float, phi_a: float, on_speed: float, pv: np.ndarray) -> float:
    """Axle torque [N*m] with which a pad that is on pushes a standing or slow wheel (our
    start model; docs/model.md, "Start from rest").

        tau_s = P * (1 - |w_on| / w_s)^+ * clip(1 - (xi_c - phi_a) / Theta, 0, 1)

    P = ``start_torque`` [N*m], Theta = ``start_stroke`` [rad], w_s = ``start_speed``
    [rad/s], w_on [rad/s] the wheel speed when the pad switched on (``on_speed``; inf when not
    known: no push), xi_c [rad] the contact angle and phi_a [rad] the contact angle at
    switch-on, so xi_c - phi_a is the travel since.  The expanding pad pushes with P at first
    and with nothing once the wheel has rolled Theta; a pad switched on at w_s or faster does
    not push at all, so (43) alone describes a rolling wheel.  Only driving pads (phi_a >= 0)
    push.  From rest with (43) switched off, the wheel rolls 2 Theta (1 - T_f / P) for
    T_f < P <= 2 T_f and P Theta / (2 T_f) for P >= 2 T_f (work of the push = work of
    friction; T_f the friction torque at the axle):
    ``test_model.py::test_a_pad_switched_on_at_rest_rolls_the_wheel_as_far_as_its_work_allows``.
    """
    p = pv[L.P_START_TORQUE]
    if p == 0.0 or phi_a < 0.0:
        return 0.0
    slow = 1.0 - abs(on_speed) / pv[L.P_START_SPEED]
    left = 1.0 - (xi_c - phi_a) / pv[L.P_START_STROKE]
    if slow <= 0.0 or left <= 0.0:
        return 0.0
    return p * slow * min(left, 1.0)


@jit_inline
def external_torque(xi1: float, xi2: float, pv: np.ndarray) -> float:
    """Axle torque [N*m] of the extensions that do not involve the actuators (0 when off)."""
    tau = 0.0
    if pv[L.P_COM_TORQUE] != 0.0:
        tau -= pv[L.P_COM_TORQUE] * math.sin(xi1 + pv[L.P_COM_PHASE])
    if pv[L.P_PLATFORM_TORQUE] != 0.0:
        tau += pv[L.P_PLATFORM_TORQUE] * math.sin(pv[L.P_PIVOT_RATIO] * xi1 + pv[L.P_PLATFORM_PHASE])
    if pv[L.P_VISCOUS] != 0.0:
        tau -= pv[L.P_VISCOUS] * xi2
    if pv[L.P_BIAS_COS] != 0.0 or pv[L.P_BIAS_SIN] != 0.0:
        tau += pv[L.P_BIAS_COS] * math.cos(xi1) + pv[L.P_BIAS_SIN] * math.sin(xi1)
    return tau + pv[L.P_BIAS_TORQUE]


@jit_inline
def acceleration(xi1: float, xi2: float, q: float, eta: float, phi_a: float, gain: float,
                 on_time: float, pv: np.ndarray, fric_dir: float = 0.0,
                 on_speed: float = math.inf) -> float:
    """Flow map of xi2: xi2' [rad/s^2] from (38)/(45) plus the enabled extensions.

    (38) divided by L:  (J/L) xi2' = r F_a sin(xi_c) q - (r + L)/L tau_f sign(xi2) + tau_ext.
    ``gain`` multiplies the actuator force (spread x retention), and the start push
    (:func:`start_push`, with ``on_speed`` [rad/s] the speed at switch-on) likewise.  ``fric_dir`` (+1/-1) fixes
    the direction of Coulomb friction for a whole flow segment (the integrator ends a segment
    with a stop event when xi2 reaches 0); with 0 it follows sign(xi2).  At xi2 == 0 friction is
    static: it cancels any net torque up to its magnitude, so a stopped wheel stays stopped
    unless driven harder than friction.
    """
    tau = 0.0
    xi_c = xi1 - eta * SECTOR
    if q != 0.0:
        if pv[L.P_BAND_LO] <= abs(xi_c) <= pv[L.P_BAND_HI]:
            tau = gain * pv[L.P_R] * force_law(xi_c, xi2, phi_a, pv) * math.sin(xi_c)
        if pv[L.P_START_TORQUE] != 0.0:
            tau += gain * start_push(xi_c, phi_a, on_speed, pv)
        if tau != 0.0 and pv[L.P_RISE_TIME] > 0.0:
            tau *= 1.0 - math.exp(-max(on_time, 0.0) / pv[L.P_RISE_TIME])
    tau += external_torque(xi1, xi2, pv)
    tf = pv[L.P_FRICTION]
    if fric_dir != 0.0:
        fric = tf * fric_dir
    elif xi2 > 0.0:
        fric = tf
    elif xi2 < 0.0:
        fric = -tf
    else:
        fric = min(max(tau, -tf), tf)
    return (tau - fric) * pv[L.P_INV_INERTIA]


@jit
def unwrap_target(n_a: float, phi_a: float, xi1: float) -> float:
    """Unwrapped target sector N = n_a + 16 k for the command u = (n_a, phi_a, phi_d).

    Actuator indices run modulo 16 while xi1 keeps growing, so (49)-(50) need the unwrapped
    sector (docs/model.md).  We take the first *future* switch-on of actuator n_a: the
    smallest N == n_a (mod 16) with N pi/8 + phi_a >= xi1, i.e. Delta+ >= 0.  So the step
    from actuator 15 to 0 becomes 15 -> 16, and braking targets (phi_a < 0) land two
    sectors ahead as Sec. III-D intends.
    """
    c = math.ceil((xi1 - phi_a) / SECTOR)
    n = n_a + N_ACTUATORS * math.ceil((c - n_a) / N_ACTUATORS)
    if n * SECTOR + phi_a < xi1:  # guard against rounding in the division
        n += N_ACTUATORS
    return float(n)


@jit
def sector_of(xi1: float) -> float:
    """Unwrapped sector floor(xi1 / (pi/8)) of eq. (40)."""
    return float(math.floor(xi1 / SECTOR))


def jump_map(xi1: float, xi2: float, q: int, eta: float, n_unwrapped: float, phi_a: float,
             phi_d: float) -> tuple[float, float, int, float, float, float]:
    """Jump map g(x, u) of (52) with the unwrapped target sector ``n_unwrapped``.

    Returns (xi1+, xi2+, q+, Delta+, delta+, eta+): xi1, xi2 unchanged, q+ = 1 - q,
    Delta+ = q (N pi/8 + phi_a - xi1), delta+ = N pi/8 + phi_d - xi1,
    eta+ = q N + (1 - q) eta.  The integrator implements the same map on its state vector.
    """
    base = n_unwrapped * SECTOR
    return (xi1, xi2, 1 - q, q * (base + phi_a - xi1), base + phi_d - xi1,
            q * n_unwrapped + (1 - q) * eta)


def in_jump_set(q: int, act_counter: float, deact_counter: float) -> bool:
    """Jump set (53): (Delta = 0 and delta != 0 and q = 0) or (Delta = 0 and delta = 0 and q = 1).

    The integrator lands events exactly, i.e. a counter is 0 at the event instant; away from
    events (x in the flow set (54)) this is False.
    """
    return (act_counter == 0.0 and deact_counter != 0.0 and q == 0) or \
           (act_counter == 0.0 and deact_counter == 0.0 and q == 1)


#: Braking inputs of Sec. III-D / V-A [rad].
BRAKE_PHI_A = math.radians(-22.0)
BRAKE_PHI_D = math.radians(-6.0)


def braking_input(xi1: float, phi_a: float = BRAKE_PHI_A,
                  phi_d: float = BRAKE_PHI_D) -> tuple[int, float, float]:
    """Braking rule (Sec. III-D): u = ((eta + 2) mod 16, phi_a < 0, phi_d < 0).

    eta is the actuator in contact, floor(xi1 / (pi/8)) of (40).  The target two pads
    ahead switches on at a negative contact angle, so its force pushes against the rolling
    direction until it switches off at phi_d (closer to 0).
    """
    if not (-SECTOR <= phi_a < phi_d <= 0.0):
        raise ValueError(f"braking needs -pi/8 <= phi_a < phi_d <= 0 rad, got phi_a={phi_a!r}, "
                         f"phi_d={phi_d!r}")
    return (int(math.floor(xi1 / SECTOR)) + 2) % N_ACTUATORS, phi_a, phi_d


def accelerating_input(xi1: float, phi_a: float, phi_d: float) -> tuple[int, float, float]:
    """Sequential acceleration (Sec. IV-B): u = ((eta + 1) mod 16, phi_a, phi_d), eta from (40)."""
    if not (0.0 <= phi_a < phi_d <= SECTOR):
        raise ValueError(f"acceleration needs 0 <= phi_a < phi_d <= pi/8 rad, got "
                         f"phi_a={phi_a!r}, phi_d={phi_d!r}")
    return (int(math.floor(xi1 / SECTOR)) + 1) % N_ACTUATORS, phi_a, phi_d
