"""Seed 002's (Ding, rolling-platform self-calibration) family: continuous rolling self-calibration and self-alignment
of a floated (ball) inertial platform.

Seed 002 (Ding, Cai, Yang, Lian: continuous rolling self-calibration and self-alignment of a floated
inertial platform). The inner sphere (platform frame p) carries three gyros and three accelerometers;
its stabilisation loops make it turn at the torquer-commanded rates plus the gyro drifts. While the
sphere rolls in the gravity field, a 45-state EKF estimates 42 error coefficients and 3 attitude angles
from the accelerometer outputs. This package holds all of it: the platform model that both the truth
generation (:func:`simulator.simulate`) and that filter (:func:`model.state_derivative`,
:func:`model.measurement`) use, the experiment that runs it (a scenario's ``experiment = "platform-rolling"``),
its method and its report. The core (:mod:`fusionbench`) knows none of it: it finds the experiment and the
method by name through their entry points (pyproject.toml, groups ``fusionbench.experiments`` and
``fusionbench.calibrators``). These notes are the model's equations; each module documents its own part.

Modules (each imports only modules above it in this list, and :mod:`fusionbench`)
----------------------------------------------------------------------------------
- ``terms``: the element formulas (attitude matrix, angle rates, drifts, outputs) in plain arithmetic, one copy for
  NumPy and numba.
- ``angles``: the attitude angles: C_pn of [phi, theta, psi] and back, the angle rates.
- ``model``: coefficients, their names and units, the error model, the filter's f(x) and h(x).
- ``scheme``: rolling schemes as data, the commanded path, the torque commands, the roll phases as figure events.
- ``simulator``: the compiled RK4 simulator of the platform (the truth).
- ``protocol``: what a calibration method is (:class:`protocol.Calibrator`), what it returns
  (:class:`protocol.CalibrationResult`), and how one is found by name.
- ``priors``: the prior standard deviations of the 45 states (shared by the filter and the observability analysis).
- ``kernels``: compiled model evaluations of the filter's inner loop.
- ``jacobians``: analytic Jacobians of f and h, in angle and in error-state form.
- ``observability``: information matrix, rank, weakest directions and output sensitivity of a scheme.
- ``figures``: the output sensitivity figure.
- ``ekf``: the method ``rolling-ekf``, seed 002's 45-state EKF (and the linearised passes after it).
- ``spec``: the scenario file's ``[platform]`` table and the per-run draw of the truth.
- ``montecarlo``: the Monte Carlo of a platform-rolling scenario and its metrics.json figures.
- ``report``: report.md and the figures of a run.
- ``experiment``: the ``platform-rolling`` experiment (:class:`fusionbench.bench.experiment.Experiment`).

Frames
------
n : navigation frame, East-North-Up (ENU). NUE is the same frame with its axes listed North-Up-East:
    ``v_NUE = P v_ENU`` with ``P = [[0, 1, 0], [0, 0, 1], [1, 0, 0]]`` (:data:`angles.P_NUE`).
p : platform frame. ``x_p`` along the X accelerometer's sensitive axis; ``y_p`` in the plane of the
    X and Y accelerometer axes, perpendicular to ``x_p``; ``z_p = x_p x y_p``.

Attitude is ``C_pn`` (p to n, ``v_n = C_pn @ v_p``). The base is static (no lever arm: the offset of
the accelerometers from the sphere's centre is optional in the paper and left out here).

Attitude angles (the EKF's three attitude states)
--------------------------------------------------
Three angles ``[phi, theta, psi]`` (rad), measured from the North-Up-East axes, in the 3-2-1 order:
``psi`` about East (NUE z), then ``theta`` about Up (NUE y), then ``phi`` about North (NUE x), each
about the *fixed* NUE axes::

    P @ C_pn = Rx(phi) @ Ry(theta) @ Rz(psi)
             = scipy Rotation.from_euler("zyx", [psi, theta, phi]).as_matrix()   # lower case: extrinsic

(``Rx, Ry, Rz`` the usual right-handed rotation matrices). Equivalently, the n-to-p transformation
matrix is ``C_np P^T = Rz(psi)^T Ry(theta)^T Rx(phi)^T``, the classical 3-2-1 product of elementary
*coordinate transformations* about z, y, x.

Why this sequence: the rolling scheme turns the platform about geographic south and east, fixed axes
of n, i.e. left-multiplies ``C_pn`` by rotations about NUE x and NUE z. A rotation about North adds to
``phi`` (the left-most factor); a rotation about East commutes through ``Rx(phi)`` and adds to ``psi``
whenever ``phi`` is 0 or 180 deg, which is where every 180-deg south segment of the paper's scheme
ends. So from the nominal start (platform axes on North-Up-East, all angles zero) the middle angle
``theta`` (about Up) stays at zero along the whole scheme and near its initial value when the start is
off by small angles: far from its singularity at +-90 deg. The *intrinsic* reading
``P @ C_pn = Rz(psi) Ry(theta) Rx(phi)`` (scipy ``"ZYX"``) does not have this property: after the
first 90-deg east turn, a turn about south becomes a turn about the intermediate y axis, and
``theta`` runs through 90 deg (gimbal lock) in the third segment (tests/test_rolling_platform.py measures
both).

Euler-angle rates. With ``w = w_np^p`` (rate of p relative to n, in p), from ``C_pn^T dC_pn/dt = [w x]``::

    w = B(angles) @ [phi', theta', psi'],   B = [Rz(psi)^T Ry(theta)^T e1 | Rz(psi)^T e2 | e3]
      = [[cos psi cos theta, sin psi, 0], [-sin psi cos theta, cos psi, 0], [sin theta, 0, 1]]
    phi'   = (cos psi w_x - sin psi w_y) / cos theta
    theta' =  sin psi w_x + cos psi w_y
    psi'   =  w_z - sin theta phi'

Error coefficients (42, order of :data:`model.COEFF_NAMES`)
-----------------------------------------------------------
Gyro axes (input I, output O, spin S), nominal and cyclic: X gyro (x_p, y_p, z_p), Y gyro
(y_p, z_p, x_p), Z gyro (z_p, x_p, y_p).

=======  =======================================  =================  ===========
index    coefficients                             SI unit            reported in
=======  =======================================  =================  ===========
0-2      gyro bias D0 (X, Y, Z)                   rad/s              deg/h
3-11     D_I, D_O, D_S of gyro X, then Y, then Z  rad/s / (m/s^2)    deg/h/g
12-20    D_IO, D_IS, D_OS of gyro X, Y, Z         rad/s / (m/s^2)^2  deg/h/g^2
21-26    gyro input-axis angles gxy, gxz, gyx,    rad                arcsec
         gyz, gzx, gzy
27-29    accelerometer bias K0 (X, Y, Z)          m/s^2              ug
30-32    accelerometer scale-factor error K1      1                  ppm
33-35    accelerometer quadratic term K2          1 / (m/s^2)        ug/g^2
36-38    accelerometer axis angles ayx, azx, azy  rad                arcsec
39-41    torquer scale-factor error KT (X, Y, Z)  1                  ppm
=======  =======================================  =================  ===========

``COEFF_SCALE`` holds the SI value of one reporting unit (g is the unit 9.80665 m/s^2 of
:mod:`fusionbench.simulation.units`): ``coeffs_SI = values_customary * COEFF_SCALE``.

Model equations
---------------
Specific force in p (static base, g = :func:`fusionbench.simulation.earth.gravity` (lat, h))::

    f^n = [0, 0, g],   f^p = C_pn^T f^n

Gyro drift of gyro i, from the specific force along its nominal I, O, S axes (the mounting angles
would change these terms only to second order, so they are ignored here)::

    eps_i = D0_i + D_I f_I + D_O f_O + D_S f_S + D_IO f_I f_O + D_IS f_I f_S + D_OS f_O f_S  (+ noise)

Gyro input-axis matrix (rows: the gyros' input axes in p; each gyro's two angles tilt its input axis
toward the two other p axes) and the stabilisation loop (each gyro's pick-off nulled: its input-axis
rate equals its torque command times ``1 + KT_i`` plus its drift)::

    G = [[1, gxy, gxz], [gyx, 1, gyz], [gzx, gzy, 1]]
    G @ w_ip^p = (I + diag(KT)) @ w_cmd^p + eps
    w_ip^p = G^-1 @ ((I + diag(KT)) @ w_cmd^p + eps)                 (exact: the simulator and the filter)
    w_ip^p ~= w_cmd^p + KT * w_cmd^p - M_g @ w_cmd^p + eps,  M_g = G - I  (first order: the paper's eq. 19)

The paper's first-order form ("small products ignored") drops ``M_g^2 w_cmd - M_g (KT w_cmd + eps)``
and higher powers of M_g. For Table 1's 120-arcsec axis angles and 1-deg/h drifts the product
``M_g eps`` alone is 3e-9 rad/s (6e-4 deg/h): as large as the paper's gyro-bias accuracy and 5-10 times
the information bound of the scheme (about 1e-4 deg/h). A filter with the first-order rate, started on the
truth of a noise-free run, drifted to a 1.3e-3 deg/h bias error; so the filter uses the exact rate too
(a 3 x 3 solve per evaluation).

Attitude kinematics (w_ie^n = [0, Omega cos L, Omega sin L], Omega = :data:`earth.OMEGA_IE`)::

    w_np^p = w_ip^p - C_pn^T w_ie^n
    dC_pn/dt = C_pn [w_np^p x] = C_pn [w_ip^p x] - [w_ie^n x] C_pn

Accelerometer outputs (m/s^2), sensitive-axis matrix A (the X axis defines p)::

    A = [[1, 0, 0], [ayx, 1, 0], [azx, azy, 1]],   f_acc = A @ f^p
    y_j = K0_j + (1 + K1_j) f_acc_j + K2_j f_acc_j^2  (+ noise)

The EKF's model (45-vector ``x = [42 coefficients, phi, theta, psi]``)::

    h(x) = y(coeffs, C_pn(angles)^T f^n)                                  (:func:`model.measurement`)
    f(x) = [0 (42), Euler rates of w_np^p (exact platform rate)]        (:func:`model.state_derivative`)

Torquing scheme and commands
----------------------------
A :class:`scheme.Scheme` is a sequence of segments, each a rotation of the platform *relative to n* about a
fixed ENU unit axis ``u`` at rate ``r`` (rad/s) for a duration (s, a whole number of command
periods); rate 0 holds the platform still relative to n (the command is then the earth rate alone).
The commanded path from the initial attitude ``C0``::

    C_path(t) = Rot_n(u, r (t - t_seg)) @ C_path(t_seg),   C_path(0) = C0

The torque command is held over each command period k (1 s) and computed from the path at the
period's middle: ``w_cmd^p = C_path(t_mid)^T (w_ie^n + r u)``, the absolute rate the platform needs
to follow the path. :data:`scheme.PAPER_SCHEME`: 0.1 deg/s about geographic south for 1800 s, about east
900 s, south 1800 s, east 900 s (5400 s; every rotation axis horizontal, so gravity sweeps through
the platform, and each platform axis turns through about 180 deg).

Holding the command constant over 1 s departs from the path by second-order terms (the earth-rate
part of the needed rate turns with the platform): of order ``r^2 Omega T^3 / 12`` per period,
coherent along a segment. Measured over the 5400-s paper scheme: 0.008 arcsec at most (0.006 at the
end); it scales with T^2 (6e-7 arcsec with 10-ms commands).

Simulator
---------
:func:`simulator.simulate` integrates the unit quaternion ``q`` of ``C_pn`` (Hamilton, scalar first,
``v_n = q v_p q*``) with the classical 4th-order Runge-Kutta method at ``sample_s`` (2 ms)::

    dq/dt = 1/2 q (x) [0, w_ip^p] - 1/2 [0, w_ie^n] (x) q

normalising ``q`` after every step. The command is held over its period; the drift is evaluated from
the current attitude at every Runge-Kutta stage (exact ``G^-1``). Noise:

* gyro: white drift, an independent normal value of standard deviation ``gyro_noise`` (rad/s) per
  sample, held over that sample (equivalent angle random walk ``gyro_noise * sqrt(sample_s)``,
  rad/sqrt(s)); the paper's "0.05 deg/h white" is read as that sigma per 2-ms sample
  (:data:`model.PAPER_GYRO_NOISE`);
* accelerometer: an independent normal value of standard deviation ``accel_noise`` (m/s^2) added to
  each filter output (the paper's 1 ug, :data:`model.PAPER_ACCEL_NOISE`).

Outputs come every ``filter_s`` (0.2 s) at ``t_k = k filter_s``, k = 1, 2, ...: the accelerometer
outputs *sampled at t_k* (instantaneous, so ``y_k = h(x(t_k)) + v_k`` holds exactly; an average over
the 0.2 s would equal the sample at the interval's middle to within ``g (r filter_s)^2 / 24``, 0.005 ug
at 0.1 deg/s), the true attitude at t_k, and the command that was held over ``(t_{k-1}, t_k]``.
The loop is compiled with numba and runs over a leading Monte Carlo axis (threads over runs); the
gyro noise is drawn with NumPy, one independent stream per run (``SeedSequence(seed).spawn``), in
chunks of about 50,000 samples, so run r's numbers do not depend on the batch size.

Every function validates its input and raises one ``ValueError`` line naming the field.
"""
