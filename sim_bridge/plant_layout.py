"""The plant kernels' shared vectors: their layouts, the base modes, and the writers of a layout's 3-vector slots.

The plant's hot path (docs/plant.md, "Speed") works on flat float64 arrays whose slots are named by layouts
(navig8_fc.core.layout: one table gives the kernels their slot constants, X.POS, and plant.py its slices,
X.POS.sl). The vectors here are read by the kernels of several modules (rigid_body, arm_dynamics, actuators,
ground_contact, joint_servo, integrator, sensors), so they sit below all of them; a layout that one module alone
indexes stays beside its kernels (arm_dynamics.SC, integrator.W, the sensors' S, NOISE, SIG). A cached kernel that
reads these layouts or calls put3/put_sym3 is decorated `njit_cached(plant_layout, ...)`: a change here recompiles
it. The physics step's helpers in the other modules (arm_sums, propulsion, contact_wrench, act_at, servo_update,
...) are `njit(inline="always")`: no cache of their own, compiled into their njit_cached callers (rigid_body.dynamics,
integrator.advance), which list their modules; as separate calls the step was ~10 % slower.
"""

from __future__ import annotations

from numba import njit

from navig8_fc.core.layout import layout

N_ACT = 5  # actuators: alpha1, alpha3 (duct tilts), w1, w2, w3 (duct 1, tail, duct 3 speeds)
N_CONTACT_MAX = 8  # ground contact points the parameter vector has room for

# State vector x
X = layout("X", pos=3,  # position of O, NED (m)
           vel=3,  # velocity of O, NED (m/s)
           quat=4,  # attitude [w, x, y, z], body FRD -> NED
           rate=3,  # body rates, FRD (rad/s)
           act=5,  # actuator outputs (alpha1, alpha3 rad; w1, w2, w3 rad/s); x[:X.ACT] is what RK4 integrates
           actd=5,  # their time derivatives
           q=3, qd=3,  # joint angles (rad) and rates (rad/s)
           qdd=3,  # joint accelerations over the current servo period (rad/s^2)
           mobj=1,  # object mass (kg), 0 when nothing is held
           qtgt=3)  # joint targets the servo used last (rad)
N_X = int(X.SIZE)
N_BASE = int(X.ACT)  # the part of x integrated by RK4

# Parameter vector p, built once by plant.py
P = layout("P", g=1,  # gravity (m/s^2)
           m0=1, j0=9,  # UAV mass (kg), inertia about O (row-major 3x3)
           ml=1, ia=1, l=1,  # link mass, transverse inertia (slender rod), length
           mount=3,  # joint-1 position relative to O, FRD
           obj_d=1, obj_r=1,  # object centre offset beyond the tip along link 3; sphere radius (0.4 m r^2)
           pf=15, pm=15,  # force and moment about O per unit U, 3x5 row-major (vehicle.propulsion_per_input)
           phi_h=20, gam_h=10,  # actuator transition matrices over h, 5 x [p11, p12, p21, p22]; inputs 5 x [g1, g2]
           phi_h2=20, gam_h2=10,  # the same over h/2 (RK4 mid stages)
           act_min=5, act_max=5,
           h=1, servo_n=1,  # physics step (s), physics steps per servo period
           vmax=1, amax=1, qlim=1,  # joint rate, acceleration and angle limits (targets clamped to +-qlim)
           stall_j=1, stall_us=1,  # fault: joint stall_j (-1: none) stops dead from stall_us on
           kn=1, cn=1, mu=1, veps=1,  # contact stiffness, damping per point; friction coeff., regularisation speed
           nc=1, cp=3 * N_CONTACT_MAX,  # number of contact points; the points, FRD relative to O
           h_us=1)  # physics step in microseconds (integer-valued)
N_P = int(P.SIZE)

# Derived quantities d, filled at the end of every advance() / evaluate()
D = layout("D", acc=3,  # absolute acceleration of O, body FRD (m/s^2)
           wdot=3,  # body angular acceleration (rad/s^2)
           spf=3,  # specific force at O, body (a_O - g), what an ideal accelerometer at O reads
           mass=1, com=3,  # total mass (kg), composite CoM relative to O, FRD
           jc=9, jo=9,  # inertia about the composite CoM and about O (3x3 row-major)
           fr_g=3, fr_nog=3,  # reaction force of the arm on the UAV with / without the arm's weight (N, FRD)
           mr_mount_g=3, mr_mount_nog=3,  # reaction moment about the mount (N m)
           mr_o_g=3, mr_o_nog=3,  # reaction moment about O
           fprop=3, mprop=3,  # propulsive force (N, FRD) and moment about O (N m)
           fcont=3, mcont=3,  # ground contact force and moment about O
           ncont=1)  # number of contact points touching
N_D = int(D.SIZE)

# Command vector: actuator commands (already validated and clamped by plant.py), joint-override flag (1.0: use
# jtgt as joint targets instead of the schedule), joint targets.
C = layout("C", act=N_ACT, jovr=1, jtgt=3)
N_C = int(C.SIZE)

# Base modes: how the floating base is constrained (analysis variants; flight uses FREE).
BASE_FREE = 0
BASE_ATTITUDE_LOCKED = 1  # w = w' = 0, translation free: the limit of an infinitely stiff attitude loop
BASE_FIXED = 2  # a_O = w' = 0: the base is held (a test stand)


@njit(cache=True)
def put3(v, at, a, b, c) -> None:
    """v[at:at + 3] = (a, b, c): one 3-vector slot of a layout."""
    v[at] = a
    v[at + 1] = b
    v[at + 2] = c


@njit(cache=True)
def put_sym3(v, at, xx, xy, xz, yy, yz, zz) -> None:
    """v[at:at + 9] = the symmetric 3x3 matrix, row-major."""
    put3(v, at, xx, xy, xz)
    put3(v, at + 3, xy, yy, yz)
    put3(v, at + 6, xz, yz, zz)
