"""Index layout of the float64 vectors the compiled core works on.

The compiled integrator keeps one wheel's complete state in a flat vector (``S_*``
indices, size ``S_SIZE``) and its parameters in another (``P_*``, size ``P_SIZE``), so a
batch of N wheels is simply an (N, S_SIZE) and an (N, P_SIZE) array.
"""

# ---- parameter vector -----------------------------------------------------------------
P_R = 0              # wheel radius r [m]
P_SIGMA1 = 1         # force law (43)
P_SIGMA2 = 2
P_SIGMA3 = 3
P_SIGMA4 = 4
P_INV_S5SQ = 5       # 1 / sigma5^2
P_SIGMA6 = 6
P_BRAKE_GAIN = 7     # braking-force model gain [1]
P_FRICTION = 8       # (r + L)/L * tau_f [N*m]
P_INV_INERTIA = 9    # 1 / (I1 + M r^2 + I33 r^2 / L^2) [1/(kg m^2)]
P_PIVOT_RATIO = 10   # r / L [1]
P_COM_TORQUE = 11    # [N*m]
P_COM_PHASE = 12     # [rad]
P_PLATFORM_TORQUE = 13  # [N*m]
P_PLATFORM_PHASE = 14   # [rad]
P_VISCOUS = 15       # [N*m*s/rad]
P_RISE_TIME = 16     # [s]
P_RET_RATE = 17      # [1/s]
P_RET_RECOVERY = 18  # [s]
P_BAND_LO = 19       # |contact angle| band [rad] outside which the force law is < e^-60 of
P_BAND_HI = 20       #   its peak and is taken as 0 (no effect on any double-precision result)
P_GAINS = 21         # 16 per-actuator gains [1]
P_BIAS_TORQUE = P_GAINS + 16   # disturbance torque c + a cos(xi1) + b sin(xi1) [N*m]: 0 in the
P_BIAS_COS = P_BIAS_TORQUE + 1  #   plant; the observer and the MPC's prediction carry the
P_BIAS_SIN = P_BIAS_TORQUE + 2  #   observer's disturbance estimate here (c, a, b)
P_READ_COS = P_BIAS_SIN + 1     # angle reading = xi1 + P_READ_COS cos(xi1) + P_READ_SIN sin(xi1)
P_READ_SIN = P_BIAS_SIN + 2     #   [rad]: an eccentric angle sensor (0 = exact reading)
P_START_TORQUE = P_READ_SIN + 1  # start push (model.start_push): axle torque [N*m] at switch-on,
P_START_STROKE = P_READ_SIN + 2  #   travel [rad] over which it falls to 0, and the switch-on
P_START_SPEED = P_READ_SIN + 3   #   speed [rad/s] at and above which there is none
P_SIZE = P_START_SPEED + 1

# ---- state vector ---------------------------------------------------------------------
S_T = 0            # simulated time [s]
S_XI1 = 1          # wheel angle [rad]
S_XI2 = 2          # wheel speed [rad/s]
S_Q = 3            # 0/1
S_ETA = 4          # unwrapped sector of the actuator of interest
S_THETA_ON = 5     # wheel angle of the next switch-on [rad] (Delta = theta_on - xi1 while q = 0)
S_THETA_OFF = 6    # wheel angle of the next switch-off [rad] (delta = theta_off - xi1)
S_PHI_A = 7        # latched activation angle [rad]
S_PHI_D = 8        # latched deactivation angle [rad]
S_ARMED = 9        # 1 while a command is latched, 0 = idle (no target: coasting, HV off)
S_ON_TIME = 10     # time since the current switch-on [s]
S_CMD_SEQ = 11     # sequence number of the latched command
S_PEND = 12        # 1 when a command waits to be latched at the next switch-off
S_PEND_NA = 13
S_PEND_PHI_A = 14
S_PEND_PHI_D = 15
S_PEND_SEQ = 16
S_AUTO = 17        # built-in open-loop schedule: 0 off, 1 next after the actuator of interest,
                   # 2 next after the sector measured at switch-off (eq. (40))
S_AUTO_PHI_A = 18
S_AUTO_PHI_D = 19
S_PRIME_LEFT = 20  # priming activations still to do
S_PRIME_PHI_A = 21
S_N_ON = 22        # switch-on events so far
S_N_OFF = 23       # switch-off events so far
S_MODE = 24        # 0 exact switching, 1 switching on firmware ticks
S_ACT_TIME = 25    # accumulated HV on-time of all actuators [s]
S_ON_SPEED = 26    # wheel speed at the current switch-on [rad/s] (inf: not known, no start push)
S_RET = 32         # 16 charge-retention states Q_i [s]
S_SIZE = S_RET + 16

AUTO_OFF = 0
AUTO_AFTER_ACTIVE = 1
AUTO_AFTER_MEASURED = 2

MODE_EXACT = 0
MODE_TICK = 1

# ---- event records written by the integrator: (time, xi1, kind, eta) -----------------
EV_ON = 1          # q 0 -> 1
EV_OFF = 2         # q 1 -> 0 (a new command latched, or none)
EV_ARM = 3         # idle -> armed (a command latched while coasting)
EV_STOP = 4        # the wheel came to rest
EV_MAX_PER_TICK = 16
