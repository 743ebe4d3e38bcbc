"""Observability of rolling schemes (baselines.rolling.observability): rank, null spaces, sensitivity."""

import numpy as np
import pytest
from scipy.linalg import expm

from baselines.rolling import angles, model
from baselines.rolling import observability as ro
from baselines.rolling import figures as rolling_figures
from baselines.rolling.jacobians import error_jacobians
from baselines.rolling.priors import prior_sigma
from baselines.rolling.scheme import PAPER_SCHEME, Scheme, commanded_path, commands
from baselines.rolling.simulator import simulate
from fusionbench.simulation import earth

LAT = np.radians(40.0)
RATE = np.radians(0.1)
SOUTH = (0.0, -1.0, 0.0)
EAST = (1.0, 0.0, 0.0)
SINGLE_AXIS = Scheme(((SOUTH, RATE, 5400.0),))
STATIC = Scheme(((EAST, 0.0, 600.0),))
D = prior_sigma()
IDX = {n: i for i, n in enumerate(ro.ERROR_STATE_NAMES)}


@pytest.fixture(scope="module")
def m_paper():
    return ro.information_matrix(PAPER_SCHEME, LAT)


@pytest.fixture(scope="module")
def m_single():
    return ro.information_matrix(SINGLE_AXIS, LAT)


def _in_subspace(V, v):
    """Norm of the projection of the unit vector v on the span of V's orthonormal columns."""
    v = v / np.linalg.norm(v)
    return np.linalg.norm(V.T @ v)


def _null_basis(M, rtol=ro.RTOL):
    _, s, Vt = np.linalg.svd(M)
    return Vt[s <= rtol * s[0]].T


def test_paper_scheme_has_full_rank_45(m_paper):
    rank, s = ro.information_rank(m_paper, return_singular_values=True)
    assert rank == 45  # seed 002's claim
    # measured: smallest 8.5e-10 of the largest, three decades above the tolerance
    assert 3e-10 < s[-1] / s[0] < 3e-9


def test_single_axis_scheme_is_deficient_and_names_what_it_cannot_see(m_single):
    rank, s = ro.information_rank(m_single, return_singular_values=True)
    assert rank == 21  # measured; clear gap: 1.8e-8 then 3.5e-17 of the largest
    assert s[20] / s[0] > 1e-9 and s[21] / s[0] < 1e-15
    d = ro.unobservable_directions(m_single)
    assert d.vectors.shape == (45, 24) and np.all(d.singular_values <= ro.RTOL * s[0])
    # theory: rolling about south keeps x_p on North, so f_x = 0 all along: every term multiplying f_x
    # (X accelerometer K1, K2 and the angles towards x; drift terms with f_x) leaves no trace at all
    zero_fx = ["K1_X", "K2_X", "A_YX", "A_ZX", "DI_X", "DIO_X", "DIS_X", "DS_Y", "DIS_Y", "DOS_Y", "DO_Z",
               "DIO_Z", "DOS_Z"]
    for name in zero_fx:
        assert d.weights[IDX[name]] > 1 - 1e-9, name
    # about the rotation axis: the X gyro's command is the constant w_x = Omega cos L - r, so a torquer
    # scale-factor error KT_X = a acts exactly as a bias D0_X = a w_x; e = (KT_X: a, D0_X: -a w_x) is unseen
    w_x = earth.OMEGA_IE * np.cos(LAT) - RATE
    v = np.zeros(45)
    v[IDX["KT_X"]], v[IDX["D0_X"]] = 1.0 / D[IDX["KT_X"]], -w_x / D[IDX["D0_X"]]  # in prior-scaled z
    assert _in_subspace(d.vectors, v) > 1 - 1e-6
    # ... as a combination: neither state alone is unobservable (measured weights 0.03 and 0.97)
    assert d.weights[IDX["D0_X"]] < 0.1 and d.weights[IDX["KT_X"]] < 0.99
    combo = [dict(t) for t in d.terms if "KT_X" in dict(t)]
    assert len(combo) == 1 and "D0_X" in combo[0]
    assert combo[0]["D0_X"] / combo[0]["KT_X"] == pytest.approx(-w_x * D[IDX["KT_X"]] / D[IDX["D0_X"]], rel=1e-4)


def test_static_platform_is_strongly_deficient():
    M = ro.information_matrix(STATIC, LAT)
    rank, s = ro.information_rank(M, return_singular_values=True)
    # theory (static alignment): the three output constants and the tilt/drift system, less the east
    # drift/azimuth pair and the horizontal output constants that duplicate the constant tilts: 3 + 5 - 2
    assert rank == 6
    assert s[5] / s[0] > 1e-9 and s[6] / s[0] < 1e-15  # measured 1.4e-8 and 2.6e-17
    # the Up (Y) accelerometer sees g all along: K0_Y = -g a and K1_Y = a cancel exactly
    g = earth.gravity(LAT, 0.0)
    v = np.zeros(45)
    v[IDX["K0_Y"]], v[IDX["K1_Y"]] = -g / D[IDX["K0_Y"]], 1.0 / D[IDX["K1_Y"]]
    assert _in_subspace(_null_basis(M), v) > 1 - 1e-6


def test_information_matrix_is_symmetric_psd_and_scales_with_the_prior(m_paper):
    assert np.array_equal(m_paper, m_paper.T)
    lam = np.linalg.eigvalsh(m_paper)
    assert lam[0] > -1e-12 * lam[-1]
    scheme = Scheme(((SOUTH, RATE, 200.0), (EAST, RATE, 200.0)))
    ms = ro.information_matrix(scheme, LAT)
    mu = ro.information_matrix(scheme, LAT, scaled=False)
    # unscaled M = D^-1 M_z D^-1, compared entry by entry relative to sqrt(M_ii M_jj)
    ref = ms / np.outer(D, D)
    norm = np.sqrt(np.outer(np.diag(mu), np.diag(mu)))
    assert np.max(np.abs(mu - ref) / norm) < 1e-9


def test_information_grows_along_the_scheme(m_paper):
    half = Scheme(PAPER_SCHEME.segments[:2])  # first 2700 s
    m_half = ro.information_matrix(half, LAT)
    lam = np.linalg.eigvalsh(m_paper - m_half)
    assert lam[0] >= -1e-9 * np.abs(lam).max()
    assert lam[-1] > 1e-3 * np.linalg.eigvalsh(m_paper)[-1]  # and really grows
    assert ro.information_rank(m_half) < 45  # measured 34 (tolerance dependent, see module notes)


def test_sensitivity_takes_whole_exponentials_once_a_coefficient_row_is_not_zero(monkeypatch):
    # the filter's model has zero coefficient rows in F_k and the sensitivity keeps only F_k's eta rows; a model whose
    # rows turn non-zero at step 10 must give H_k Phi(t_k, 0) from the whole F_k, the steps before it included
    scheme = Scheme(((SOUTH, RATE, 20.0), (EAST, RATE, 20.0)))
    C0, coeffs = angles.angles_to_dcm([0.1, 0.02, -0.3]), model.coeff_vector(True, D0_X=1.0, G_XY=30.0)
    steps = []

    def drifting(x, w_cmd, lat, h=0.0):
        F, H = error_jacobians(x, w_cmd, lat, h)
        steps.append(None)
        if len(steps) > 10:
            F = F.copy()
            F[0, model.N_COEFFS + 2] = 1e-2  # a coefficient that moves with the azimuth error
        return F, H

    monkeypatch.setattr(ro, "error_jacobians", drifting)
    t, S = ro._output_sensitivity(scheme, LAT, 0.0, C0, coeffs, 1.0)
    steps.clear()
    ang = angles.dcm_to_angles(commanded_path(scheme, C0, np.arange(41.0)))
    cmd = commands(scheme, C0, LAT)
    FH = [drifting(np.concatenate([coeffs, ang[k]]), cmd[min(k, 39)], LAT) for k in range(41)]
    P, want = np.eye(45), []
    for k in range(40):
        P = expm(FH[k][0]) @ P
        want.append(FH[k + 1][1] @ P)
    assert np.array_equal(t, np.arange(1.0, 41.0))
    assert np.abs(S[:10] - want[:10]).max() <= 1e-12 * np.abs(want[:10]).max()
    assert np.abs(S - want).max() <= 1e-9 * np.abs(want).max()
    assert np.abs(S[-1, :, 0]).max() > 1e-6 * np.abs(S[-1]).max()  # the coefficient row reaches the outputs


def test_matches_the_plain_definition_with_full_45x45_exponentials():
    # independent computation of M = sum Phi(t_k,0)^T H_k^T R^-1 H_k Phi(t_k,0) with expm of the full F_k,
    # at non-zero nominal coefficients (the drift Jacobian then varies with the attitude)
    scheme = Scheme(((SOUTH, RATE, 30.0), (EAST, RATE, 30.0)))
    coeffs = model.coeff_vector(True, D0_X=1.0, DI_Y=0.5, DO_Z=0.5, DIO_X=0.2, G_XY=30.0, KT_Z=100.0, K1_X=50.0)
    C0 = angles.angles_to_dcm([0.1, 0.02, -0.3])
    t = np.arange(61.0)
    ang = angles.dcm_to_angles(commanded_path(scheme, C0, t))
    cmd = commands(scheme, C0, LAT)
    r2 = model.PAPER_ACCEL_NOISE ** 2
    P, M = np.eye(45), np.zeros((45, 45))
    for k in range(60):
        F, _ = error_jacobians(np.concatenate([coeffs, ang[k]]), cmd[k], LAT)
        P = expm(F) @ P
        _, H = error_jacobians(np.concatenate([coeffs, ang[k + 1]]), cmd[min(k + 1, 59)], LAT)
        M += (H @ P).T @ (H @ P) / r2
    got = ro.information_matrix(scheme, LAT, C0=C0, coeffs=coeffs, scaled=False)
    norm = np.sqrt(np.outer(np.diag(M), np.diag(M)))
    assert np.max(np.abs(got - M) / norm) < 1e-8


def test_accelerometer_bias_appears_one_to_one():
    t, S = ro.sensitivity_curves(PAPER_SCHEME, LAT)
    assert t.shape == (5400,) and S.shape == (5400, 3, 45)
    assert t[0] == 1.0 and t[-1] == 5400.0
    j = IDX["K0_X"]
    np.testing.assert_allclose(S[:, 0, j], D[j], rtol=1e-12, atol=0)
    assert np.all(np.abs(S[:, 1:, j]) <= 1e-15 * D[j])


def test_sensitivity_matches_the_nonlinear_simulator():
    # independent: half a prior sigma of a coefficient in simulate (exact G^-1, RK4 at 2 ms, no noise)
    # changes the outputs by half the sensitivity curve (measured within 0.15 %)
    scheme = Scheme(((SOUTH, RATE, 300.0), (EAST, RATE, 300.0)))
    names = ["D0_X", "G_XY", "KT_Z", "DO_Y"]
    c = np.zeros((len(names) + 1, 42))
    for r, n in enumerate(names):
        c[r + 1, IDX[n]] = 0.5 * D[IDX[n]]
    run = simulate(scheme, c, angles.angles_to_dcm(np.zeros(3)), LAT, gyro_noise=0.0, accel_noise=0.0)
    t, S = ro.sensitivity_curves(scheme, LAT)
    sel = np.isclose(run.t % 1.0, 0.0) | np.isclose(run.t % 1.0, 1.0)
    np.testing.assert_allclose(run.t[sel], t)
    for r, n in enumerate(names):
        dy = run.y_clean[r + 1, sel] - run.y_clean[0, sel]
        pred = 0.5 * S[:, :, IDX[n]]
        assert np.abs(dy - pred).max() < 5e-3 * np.abs(pred).max(), n


def test_weakest_directions_of_a_full_rank_scheme(m_paper):
    d = ro.unobservable_directions(m_paper)
    assert d.vectors.shape == (45, 0)
    d = ro.unobservable_directions(m_paper, count=1)
    # measured: the quadratic accelerometer terms of X and Y together
    assert {n for n, _ in d.terms[0][:2]} == {"K2_X", "K2_Y"}
    assert d.singular_values[0] == pytest.approx(np.linalg.eigvalsh(m_paper)[0], rel=1e-6)


def test_figure_is_written(tmp_path):
    scheme = Scheme(((SOUTH, RATE, 120.0), (EAST, RATE, 60.0)))
    t, S = ro.sensitivity_curves(scheme, LAT)
    path = rolling_figures.sensitivity_figure(t, S, path=tmp_path / "sens.png")
    data = (tmp_path / "sens.png").read_bytes()
    assert path.endswith("sens.png") and data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


@pytest.mark.parametrize("kwargs, field", [
    ({"step_s": 0.3}, "step_s"),
    ({"coeffs": np.zeros(41)}, "coeffs"),
    ({"accel_noise": 0.0}, "accel_noise"),
    ({"C0": np.eye(2)}, "C0"),
])
def test_bad_input_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        ro.information_matrix(STATIC, LAT, **kwargs)


def test_rank_rejects_bad_input():
    with pytest.raises(ValueError, match="M"):
        ro.information_rank(np.zeros((3, 4)))
    with pytest.raises(ValueError, match="rtol"):
        ro.information_rank(np.eye(3), rtol=2.0)
