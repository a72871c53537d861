"""Published results we compare against (Ly et al., HASEL rolling soft wheel).

Linear speeds in the paper are converted to wheel speed with r = 0.157 m (Table I).
"""
from __future__ import annotations

WHEEL_RADIUS = 0.157  # [m], Table I

#: Table II, phi_d = 22 deg: phi_a [deg] -> (rise time t_r [s], steady linear speed [m/s]).
#: phi_a = 11 deg has no entry at phi_d = 22 deg.
TABLE_II_PHI_D22 = {
    1: (29.17, 0.57),
    3: (26.23, 0.43),
    5: (27.04, 0.39),
    7: (23.83, 0.32),
    9: (12.57, 0.21),
}

#: Table III: phi_a [deg] -> (RMSE [m/s], R^2, steady-state error [m/s]) of the paper's fit.
TABLE_III = {
    1: (0.17, 0.97, 0.12),
    3: (0.32, 0.82, 0.18),
    5: (0.16, 0.93, 0.09),
    7: (0.24, 0.73, 0.27),
    9: (0.13, 0.72, 0.10),
}


def table_ii_speed(phi_a_deg: int) -> float | None:
    """Measured steady wheel speed [rad/s] of Table II at phi_d = 22 deg, or None."""
    row = TABLE_II_PHI_D22.get(phi_a_deg)
    return None if row is None else row[1] / WHEEL_RADIUS


def table_ii_rise(phi_a_deg: int) -> float | None:
    """Measured rise time [s] of Table II at phi_d = 22 deg, or None."""
    row = TABLE_II_PHI_D22.get(phi_a_deg)
    return None if row is None else row[0]


#: Fig. 11 / Sec. V-C: reference [rad/s] -> (steady-state error [%], NRMSE [1]) without and
#: with the disturbance estimator.
FIG11_WITHOUT_ESTIMATOR = {1.0: (9.80, 0.133), 1.5: (7.82, 0.098), 2.0: (5.37, 0.067),
                           2.5: (None, 0.039)}
FIG11_WITH_ESTIMATOR = {1.0: (0.80, 0.090), 1.5: (0.96, 0.053), 2.0: (0.52, 0.046),
                        2.5: (None, 0.042)}
#: Fig. 11(c): braking fall time 2.6 -> 2.0 rad/s [s].
FIG11_FALL_TIME = 1.2
