"""The LQR baseline's Rust design and filter (accd_sim::control) against SciPy and numpy.

The reference below is the design as SciPy computes it (``scipy.linalg.solve_discrete_are``, a
QZ method through LAPACK, and numpy's pseudo-inverse): the same equations the Rust core solves
by structured doubling in fixed-order arithmetic. SciPy is a test-only dependency.

Tolerances, with what was measured on the default plant (132 plant and 140 observer states):
the LQR's Riccati solution within 1e-10 of SciPy's (relative, Frobenius norm; measured 2e-14),
its gain within 1e-10 of the largest entry (1e-13), its relative residual below 1e-13 (7e-15,
SciPy's 1.2e-14); the filter's ill-conditioned equation (its solution's diagonal spans six
decades) within 1e-9 (7e-12), the Kalman gain within 1e-8 (5e-11), the relative residual below
1e-10 (5.5e-12, SciPy's 2.3e-13); the reference gain within 1e-9 of numpy's pseudo-inverse
solution (1.4e-12); the spectral radii within 1e-9 of numpy's eigenvalues' (1e-12).
"""

import numpy as np
import pytest

from accd_gym.control.lqr import LqrPolicy, default_tuning, design, linearize
from accd_gym.envs.task import ACT_DIM, OBS_DIM, OBSERVATION_SCALE, OBSERVATION_TABLE, observation_indices

scipy_linalg = pytest.importorskip("scipy.linalg")

MEASURED = np.array([i for i in range(OBS_DIM) if i != int(observation_indices("time_left")[0])])
BOOM_POS = observation_indices("boom_rel_x", "boom_rel_y", "boom_rel_z")
BOOM_VEL = observation_indices("boom_rel_vx", "boom_rel_vy", "boom_rel_vz")
MEAS_SIGMA = {
    "boom_rel_x": 0.01, "boom_rel_y": 0.01, "boom_rel_z": 0.01,
    "boom_rel_vx": 0.01, "boom_rel_vy": 0.01, "boom_rel_vz": 0.01,
    "accd_dx": 0.01, "accd_dy": 0.01, "accd_dz": 0.01,
    "accd_vx": 0.01, "accd_vy": 0.01, "accd_vz": 0.01,
    "quat_w": 1e-4, "quat_x": 1e-4, "quat_y": 1e-4, "quat_z": 1e-4,
    "rate_p": 1e-3, "rate_q": 1e-3, "rate_r": 1e-3,
    "flap_right": 1e-4, "flap_left": 1e-4, "flap_top": 1e-4, "flap_bottom": 1e-4,
    "tension": 100.0,
}


def problems(lin, t):
    """The two Riccati problems and the reference problem of the design, built in numpy."""
    a, b, e, c = lin.a, lin.b, lin.e, lin.c
    n = a.shape[0]
    names = lin.state_names
    steps = np.asarray(lin.steps)
    sp, sv = OBSERVATION_SCALE["boom_rel_x"], OBSERVATION_SCALE["boom_rel_vx"]
    cp = -c[BOOM_POS] / sp
    cpv = -c[BOOM_VEL] / sv
    att = np.array([names.index(k) for k in ("att_x", "att_y", "att_z")])
    rates = np.array([names.index(k) for k in ("p", "q", "r")])
    q = t.q_position * cp[1:].T @ cp[1:] + t.q_velocity * cpv.T @ cpv + 1e-9 * np.eye(n)
    q[att, att] += t.q_attitude
    q[rates, rates] += t.q_rate
    r = t.r_flap * np.eye(ACT_DIM)
    m = np.block([[a - np.eye(n), b], [cp[1:], np.zeros((2, ACT_DIM))]])
    d = np.concatenate([steps * 1e3, np.ones(ACT_DIM)])
    rhs = np.block([[-e, np.zeros((n, 2))], [np.zeros((2, 2)), np.eye(2)]])
    nz = n + 8
    f = np.zeros((nz, nz))
    f[:n, :n] = a
    f[:n, n:n + 2] = e
    f[n:n + 2, n:n + 2] = np.eye(2)
    f[n + 2:n + 5, n + 2:n + 5] = np.eye(3)
    f[n + 2:n + 5, n + 5:] = lin.dt * np.eye(3)
    f[n + 5:, n + 5:] = np.eye(3)
    h = np.zeros((len(MEASURED), nz))
    h[:, :n] = c[MEASURED]
    rows = list(MEASURED)
    for j in range(3):
        h[rows.index(BOOM_POS[j]), n + 2 + j] = sp
        h[rows.index(BOOM_VEL[j]), n + 5 + j] = sv
    qn = np.zeros((nz, nz))
    qn[:n, :n] = t.wind_white**2 * e @ e.T + np.diag((t.model_noise * 1e3 * steps) ** 2)
    qn[n:n + 2, n:n + 2] = t.wind_walk**2 * np.eye(2)
    qn[n + 2:n + 5, n + 2:n + 5] = 1e-6 * np.eye(3)
    qn[n + 5:, n + 5:] = t.boom_accel**2 * np.eye(3)
    sigma = np.array([MEAS_SIGMA[OBSERVATION_TABLE[i][0]] * OBSERVATION_TABLE[i][2] for i in MEASURED])
    rn = np.diag((t.meas_noise * sigma) ** 2)
    return dict(a=a, b=b, q=q, r=r, m=m, d=d, rhs=rhs, f=f, h=h, qn=qn, rn=rn, n=n)


def residual(x, a, b, q, r):
    """The relative residual of ``X = A^T X A - A^T X B (R + B^T X B)^-1 B^T X A + Q``."""
    axa = a.T @ x @ a
    axb = a.T @ x @ b
    corr = axb @ np.linalg.solve(r + b.T @ x @ b, axb.T)
    scale = max(np.linalg.norm(t) for t in (x, axa, corr, q))
    return np.linalg.norm(x - (axa - corr + q)) / scale


@pytest.fixture(scope="module", params=[{}, {"tether": {"segments": 10, "length": 200.0}}], ids=["default", "short"])
def case(request):
    lin = linearize(request.param)
    t = default_tuning()
    return lin, t, problems(lin, t), design(lin, t)


def test_the_lqr_riccati_solution_matches_scipy(case):
    lin, t, p, d = case
    from accd_gym import _core

    rust = _core.lqr_design(lin, [getattr(t, k) for k in t.__dataclass_fields__])
    x = rust.lqr_solution
    ref = scipy_linalg.solve_discrete_are(p["a"], p["b"], p["q"], p["r"])
    assert residual(x, p["a"], p["b"], p["q"], p["r"]) < 1e-13
    assert np.linalg.norm(x - ref) < 1e-10 * np.linalg.norm(ref)
    k = np.linalg.solve(p["r"] + p["b"].T @ ref @ p["b"], p["b"].T @ ref @ p["a"])
    assert np.abs(d.k - k).max() < 1e-10 * np.abs(k).max()
    assert d.closed_loop_radius == pytest.approx(np.max(np.abs(np.linalg.eigvals(p["a"] - p["b"] @ d.k))), rel=1e-9)


def test_the_kalman_riccati_solution_matches_scipy(case):
    lin, t, p, d = case
    from accd_gym import _core

    rust = _core.lqr_design(lin, [getattr(t, k) for k in t.__dataclass_fields__])
    f, h, qn, rn = p["f"], p["h"], p["qn"], p["rn"]
    x = rust.filter_solution
    ref = scipy_linalg.solve_discrete_are(f.T, h.T, qn, rn)
    ref = 0.5 * (ref + ref.T)
    ours, scipys = residual(x, f.T, h.T, qn, rn), residual(ref, f.T, h.T, qn, rn)
    assert ours < 1e-10, (ours, scipys)
    assert d.residuals[1] == pytest.approx(ours, rel=1e-3)  # the residual the Rust solver checked
    assert np.linalg.norm(x - ref) < 1e-9 * np.linalg.norm(ref)
    l_ref = ref @ h.T @ np.linalg.inv(h @ ref @ h.T + rn)
    assert np.abs(d.l - l_ref).max() < 1e-8 * np.abs(l_ref).max()
    radius = np.max(np.abs(np.linalg.eigvals((np.eye(f.shape[0]) - d.l @ h) @ f)))
    assert d.observer_radius == pytest.approx(radius, rel=1e-9)
    assert np.array_equal(d.f, f) and np.array_equal(d.h, h)


def test_the_reference_is_numpys_minimum_norm_solution(case):
    lin, t, p, d = case
    n = p["n"]
    sol = p["d"][:, None] * (np.linalg.pinv(p["m"] * p["d"][None, :], rcond=1e-10) @ p["rhs"])
    k_ff = sol[n:] + d.k @ sol[:n]
    assert np.abs(d.k_ff - k_ff).max() < 1e-9 * np.abs(k_ff).max()


def numpy_filter(d, obs, z, u, fresh):
    """One step of the filter and control law as the numpy code before the Rust core wrote it."""
    y = obs[:, MEASURED] - d.y_trim
    prior = z @ d.f.T + u @ d.g.T
    prior[fresh] = 0.0
    z = prior + (y - prior @ d.h.T) @ d.l.T
    n = d.n
    reference = np.concatenate([z[:, n:n + 2], z[:, n + 3:n + 5]], axis=1)
    u = np.clip(-z[:, :n] @ d.k.T + reference @ d.k_ff.T, -1.0, 1.0)
    return z, u


def _observations(rng, rows):
    obs = rng.uniform(-0.3, 0.3, (rows, OBS_DIM)).astype(np.float32)
    obs[:, observation_indices("quat_w")] = 1.0
    obs[:, observation_indices("time_left")] = 1.0
    return obs


def test_the_filter_step_matches_the_numpy_reference():
    policy = LqrPolicy.for_config()
    d = policy.design
    rng = np.random.default_rng(0)
    rows = 5
    z = np.zeros((rows, d.f.shape[0]))
    u = np.zeros((rows, ACT_DIM))
    fresh = np.ones(rows, dtype=bool)
    policy.reset()
    for step in range(30):
        obs = _observations(rng, rows)
        got = policy.predict(obs)
        z, u = numpy_filter(d, obs.astype(np.float64), z, u, fresh)
        fresh[:] = False
        state = policy.get_state()
        assert np.abs(state["z"] - z).max() <= 1e-9 * max(1.0, np.abs(z).max()), step
        assert np.abs(got - u.astype(np.float32)).max() <= 1e-6, step
        offset = rng.uniform(-0.1, 0.1, (rows, ACT_DIM))
        policy.sent(offset)
        u = u + offset
        if step == 10:
            policy.reset(np.array([True, False, False, True, False]))
            fresh[[0, 3]] = True


def test_the_filter_step_is_bitwise_the_same_for_any_batch_split():
    # 7 envs as one batch, as batches of 3 (and 1 left) and of 1, with commands sent off the
    # filter's: every row's commands have the same bits.
    policy = LqrPolicy.for_config()
    rng = np.random.default_rng(1)
    obs = rng.uniform(-0.3, 0.3, (20, 7, OBS_DIM)).astype(np.float32)
    obs[..., observation_indices("quat_w")] = 1.0
    off = rng.uniform(-0.1, 0.1, (20, 7, ACT_DIM))
    runs = []
    for rows in (7, 3, 1):
        starts = range(0, 7, rows)
        chunks = [LqrPolicy(policy.design) for _ in starts]
        out = []
        for o, d in zip(obs, off):
            out.append(np.concatenate([c.predict(o[i:i + rows]) for c, i in zip(chunks, starts)]))
            for c, i in zip(chunks, starts):
                c.sent(d[i:i + rows])
        runs.append(np.array(out))
    assert np.array_equal(runs[0].view(np.uint32), runs[1].view(np.uint32))
    assert np.array_equal(runs[0].view(np.uint32), runs[2].view(np.uint32))
    assert np.abs(runs[0]).max() > 0.0
