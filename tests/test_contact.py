"""jrigid.contact: impulses against hand-derived results, and bounces against closed forms.

The impulse tests use bodies whose response is known on paper: a sphere hit below its
centre (point-mass bounce, rolling with friction, sliding), a rod landing on its end or
level on one end (``m_eff = M`` and ``M/4``), the energy loss ``(1 − e²) ½ m_eff u_n²``.
General random states check the balance laws an impulse at a point must obey. The
simulated bounces of a ball are compared with the closed-form bouncing-ball sequence.
Every ``simulate_bounces`` call here uses 8 contact points, the shape the falling-box
experiment uses, so the compiled segment solver is shared.
"""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from jrigid import contact, impacts, inertia, initial
from jrigid import quaternion as quat
from jrigid.body import RigidBody
from jrigid.integrate import simulate
from jrigid.scene import FreeFlight, Gravity, Scene

N = np.array([0.0, 0.0, 1.0])
impulse = jax.jit(contact.contact_impulse)
apply = jax.jit(contact.apply_impulse)
effective_mass = jax.jit(contact.effective_mass)


def kinetic(m, moments, q, v, omega):
    return 0.5 * m * np.dot(v, v) + 0.5 * np.dot(omega, np.asarray(moments) * omega)


def after(m, moments, q, v, omega, r, e, mu):
    P = impulse(m, moments, q, v, omega, r, N, e, mu)
    v2, w2 = apply(m, moments, q, v, omega, r, P)
    return np.array(P), np.array(v2), np.array(w2)


def contact_velocity(q, v, omega, r):
    R = Rotation.from_quat(np.array(q, float), scalar_first=True)
    return np.array(v, float) + np.cross(R.apply(np.array(omega, float)), r)


# --------------------------------------------------------------------------- sphere


@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_sphere_frictionless_bounce_is_a_point_mass_bounce(e):
    m, a = 2.0, 0.3
    moments = inertia.sphere(m, a)
    q, v, w = np.array([1.0, 0, 0, 0]), np.array([0.7, -0.2, -3.0]), np.array([0.1, 0.4, 2.0])
    P, v2, w2 = after(m, moments, q, v, w, np.array([0, 0, -a]), e, 0.0)
    # contact straight below the centre: no lever arm, m_eff = m, P = (1 + e) m |v_z| n
    np.testing.assert_allclose(P, [0, 0, (1 + e) * m * 3.0], atol=1e-12)
    np.testing.assert_allclose(v2, [0.7, -0.2, 3.0 * e], atol=1e-12)
    np.testing.assert_allclose(w2, w, atol=1e-12)


def test_sphere_with_sticking_friction_leaves_rolling_at_five_sevenths():
    # angular momentum about the contact point: m u a = m u' a + (2/5) m a² ω', ω' a = u'
    m, a, u, wz, e = 1.5, 0.2, 2.0, 1.0, 0.6
    moments = inertia.sphere(m, a)
    q = np.array([1.0, 0, 0, 0])
    r = np.array([0, 0, -a])
    P, v2, w2 = after(m, moments, q, np.array([u, 0, -wz]), np.zeros(3), r, e, 10.0)
    np.testing.assert_allclose(v2, [5 * u / 7, 0, e * wz], atol=1e-12)
    np.testing.assert_allclose(w2, [0, 5 * u / (7 * a), 0], atol=1e-12)
    np.testing.assert_allclose(contact_velocity(q, v2, w2, r)[:2], 0, atol=1e-12)


def test_sphere_sliding_friction_impulse_is_mu_times_normal():
    # sliding (μ (1+e) w < 2u/7): P_t = −μ (1+e) m w; ω_y' = a μ (1+e) m w / I
    m, a, u, wz, e, mu = 1.0, 0.25, 3.0, 1.0, 0.5, 0.2
    moments = inertia.sphere(m, a)
    q = np.array([1.0, 0, 0, 0])
    P, v2, w2 = after(m, moments, q, np.array([u, 0, -wz]), np.zeros(3), [0, 0, -a], e, mu)
    pn = (1 + e) * m * wz
    np.testing.assert_allclose(P, [-mu * pn, 0, pn], atol=1e-12)
    np.testing.assert_allclose(v2, [u - mu * pn / m, 0, e * wz], atol=1e-12)
    np.testing.assert_allclose(w2, [0, a * mu * pn / float(moments[1]), 0], atol=1e-12)


def test_sphere_bounce_in_float32(float32):
    m, a, e = 1.0, 0.3, 0.5
    P = contact.contact_impulse(m, inertia.sphere(m, a), jnp.array([1.0, 0, 0, 0]),
                                jnp.array([0.5, 0, -2.0]), jnp.zeros(3), jnp.array([0, 0, -a]),
                                jnp.asarray(N, jnp.float32), e, 0.0)  # fmt: skip
    assert P.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(P), [0, 0, (1 + e) * m * 2.0], rtol=1e-6, atol=1e-6)


def test_separating_point_gets_no_impulse():
    P = impulse(1.0, jnp.ones(3), jnp.array([1.0, 0, 0, 0]), jnp.array([0.0, 0, 1.0]),
                jnp.zeros(3), jnp.array([0, 0, -0.5]), jnp.asarray(N), 0.5, 0.3)  # fmt: skip
    np.testing.assert_array_equal(np.asarray(P), 0.0)


# --------------------------------------------------------------------------- rod


def rod(m=1.0, length=2.0):
    return inertia.solid_cylinder(m, 0.01, length), m, length  # axis along body z


@pytest.mark.parametrize("angle_deg", [0.0, 20.0, 45.0, 70.0, 90.0])
@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_rod_effective_mass_and_energy_loss(angle_deg, e):
    moments, m, length = rod()
    angle = math.radians(angle_deg)  # tilt of the rod axis from the vertical
    q = np.array(quat.from_axis_angle(jnp.array([0.0, 1.0, 0.0]), angle))
    axis = Rotation.from_quat(q, scalar_first=True).apply([0, 0, 1])
    r = -0.5 * length * axis  # the lower end
    # hand result: 1/m_eff = 1/m + |r × n|² / I_perp (r × n is normal to the rod axis)
    arm = 0.5 * length * math.sin(angle)
    m_eff = 1.0 / (1.0 / m + arm**2 / float(moments[0]))
    assert float(effective_mass(m, moments, q, r, N)) == pytest.approx(m_eff, rel=1e-12)
    if angle_deg == 0.0:
        assert m_eff == pytest.approx(m)  # on its end: a point mass
    if angle_deg == 90.0:
        assert m_eff == pytest.approx(m / 4, rel=1e-3)  # level thin rod on one end
    v, w = np.array([0.3, 0.0, -2.0]), np.zeros(3)
    un = -2.0
    _, v2, w2 = after(m, moments, q, v, w, r, e, 0.0)
    lost = kinetic(m, moments, q, v, w) - kinetic(m, moments, q, v2, w2)
    assert lost == pytest.approx((1 - e * e) * 0.5 * m_eff * un * un, rel=1e-10, abs=1e-13)
    assert contact_velocity(q, v2, w2, r)[2] == pytest.approx(-e * un, rel=1e-10)


# --------------------------------------------------------------------------- balance laws

unit = st.floats(-1.0, 1.0)
vec = st.tuples(unit, unit, unit).map(np.array)


@settings(max_examples=40, deadline=None)
@given(
    qv=st.tuples(unit, unit, unit, unit).filter(lambda t: np.linalg.norm(t) > 0.2),
    v=vec, w=vec, r=vec,
    e=st.floats(0.0, 1.0), mu=st.sampled_from([0.0, 0.1, 0.5, 2.0]),
)  # fmt: skip
def test_impulse_balance_laws(qv, v, w, r, e, mu):
    m, moments = 1.3, np.array([0.4, 0.7, 0.9])
    q = np.asarray(qv) / np.linalg.norm(qv)
    v = v * 3 - np.array([0, 0, 2.0])  # mostly approaching
    R = Rotation.from_quat(q, scalar_first=True)
    P, v2, w2 = after(m, moments, q, v, w * 3, r, e, mu)
    u1 = contact_velocity(q, v, w * 3, r)
    u2 = contact_velocity(q, v2, w2, r)
    # linear momentum changes by P; angular momentum about the contact point is unchanged
    np.testing.assert_allclose(m * (v2 - v), P, atol=1e-12)

    def L_contact(vv, ww):
        return R.apply(moments * ww) + m * np.cross(-r, vv)

    np.testing.assert_allclose(L_contact(v2, w2), L_contact(v, w * 3), atol=1e-11)
    if u1[2] >= 0:
        np.testing.assert_array_equal(P, 0.0)
        return
    # restitution along the normal, inside the friction cone, pushing out of the floor
    assert u2[2] == pytest.approx(-e * u1[2], rel=1e-9, abs=1e-12)
    assert P[2] >= 0
    assert np.hypot(P[0], P[1]) <= mu * P[2] * (1 + 1e-9) + 1e-12
    if mu == 0.0:
        np.testing.assert_allclose(P[:2], 0.0, atol=1e-14)
    # no impact creates energy, with or without friction
    assert kinetic(m, moments, q, v2, w2) <= kinetic(m, moments, q, v, w * 3) * (1 + 1e-12)


def test_elastic_impacts_with_friction_never_create_energy():
    """Newton's restitution with sticking friction raised the kinetic energy in 20-45 %
    of random elastic impacts (by up to +54 %); the impulse is now pulled towards the
    frictionless one just far enough. Where Newton's impulse loses energy it is kept."""
    from jrigid import impacts

    rng = np.random.default_rng(3)
    m, moments, n = 2.0, jnp.array([0.3, 0.5, 0.7]), jnp.array([0.0, 0.0, 1.0])
    q = jax.vmap(quat.normalize)(jnp.asarray(rng.normal(size=(2000, 4))))
    r, v = jnp.asarray(0.5 * rng.normal(size=(2000, 3))), jnp.asarray(rng.normal(size=(2000, 3)))
    w = jnp.asarray(2.0 * rng.normal(size=(2000, 3)))

    def energy_change(q, v, w, r, mu):
        P = impacts.contact_impulse(m, moments, q, v, w, r, n, 1.0, mu)
        v2, w2 = impacts.apply_impulse(m, moments, q, v, w, r, P)
        before = 0.5 * m * v @ v + 0.5 * w @ (moments * w)
        after = 0.5 * m * v2 @ v2 + 0.5 * w2 @ (moments * w2)
        u2 = v2 + jnp.cross(quat.rotate(q, w2), r)
        u1 = v + jnp.cross(quat.rotate(q, w), r)
        return (after - before) / before, u1[2], u2[2], P

    for mu in (0.1, 0.3, 1.0):
        gain, u1, u2, P = jax.vmap(energy_change, in_axes=(0, 0, 0, 0, None))(q, v, w, r, mu)
        hit = np.asarray(u1) < 0
        assert hit.sum() > 800
        assert np.max(np.asarray(gain)[hit]) <= 1e-12
        np.testing.assert_allclose(np.asarray(u2)[hit], -np.asarray(u1)[hit], rtol=1e-9)
        P = np.asarray(P)[hit]
        assert np.all(np.hypot(P[:, 0], P[:, 1]) <= mu * P[:, 2] * (1 + 1e-9))
        # the impulses moved back land on the energy they had (no more is taken)
        assert np.mean(np.abs(np.asarray(gain)[hit]) < 1e-9) > 0.03


@pytest.mark.parametrize("mu", [0.05, 0.3, 1.0, 5.0])
def test_planar_friction_never_reverses_the_slip(mu):
    # a tilted box corner hits the floor sliding in +x: afterwards it slides in +x or sticks
    m, moments = 1.0, np.array(inertia.box(1.0, 1.0, 0.6, 0.3))
    q = np.array(quat.from_axis_angle(jnp.array([0.0, 1.0, 0.0]), 0.5))
    r = Rotation.from_quat(q, scalar_first=True).apply([-0.5, 0.0, -0.15])
    for w_y in (-6.0, -2.0, 0.0, 2.0, 6.0):
        v, w = np.array([1.0, 0, -2.0]), np.array([0.0, w_y, 0.0])
        u1 = contact_velocity(q, v, w, r)
        _, v2, w2 = after(m, moments, q, v, w, r, 0.5, mu)
        u2 = contact_velocity(q, v2, w2, r)
        assert u2[1] == pytest.approx(0.0, abs=1e-12)  # stays planar
        assert u2[0] * np.sign(u1[0]) >= -1e-12


# --------------------------------------------------------------------------- geometry


def test_box_corners_and_positions_match_scipy():
    size = (1.0, 0.6, 0.3)
    c = np.array(contact.box_corners(size))
    assert c.shape == (8, 3)
    np.testing.assert_allclose(np.sort(np.unique(c[:, 0])), [-0.5, 0.5])
    np.testing.assert_allclose(np.sort(np.unique(c[:, 2])), [-0.15, 0.15])
    p = np.asarray(contact.box_corners(size, planar=True))
    assert p.shape == (4, 3) and np.all(p[:, 1] == 0)
    q = np.array(quat.normalize(jnp.array([0.9, 0.2, -0.3, 0.1])))
    x, v, w = np.array([1.0, 2.0, 3.0]), np.array([0.1, 0.2, 0.3]), np.array([1.0, -2.0, 0.5])
    R = Rotation.from_quat(q, scalar_first=True)
    np.testing.assert_allclose(contact.point_positions(q, x, c), x + R.apply(c), atol=1e-12)
    expect = v + np.cross(R.apply(w), R.apply(c))
    np.testing.assert_allclose(contact.point_velocities(q, w, v, c), expect, atol=1e-12)


def test_floor_and_entry_points_reject_bad_input():
    pts = contact.box_corners((1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="restitution"):
        contact.Floor(pts, 0.0, 1.5, 0.0)
    with pytest.raises(ValueError, match="friction"):
        contact.Floor(pts, 0.0, 0.5, -1.0)
    with pytest.raises(ValueError, match="shape"):
        contact.Floor(jnp.zeros(3))
    with pytest.raises(ValueError, match="restitution must be a scalar"):
        contact.Floor(pts, 0.0, jnp.array([0.5, 0.5]))  # a raw TypeError before
    body = RigidBody(inertia.box(1.0, 1.0, 1.0, 1.0), 1.0)
    scene = Scene(body, FreeFlight(), (Gravity(), contact.Floor(pts)))
    state = initial.from_omega(None, (0.0, 0.0, 0.0), x=(0.0, 0.0, 2.0), v=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="simulate_bounces"):
        simulate(scene, state, jnp.linspace(0.0, 1.0, 3))
    with pytest.raises(ValueError, match="Floor"):
        contact.simulate_bounces(Scene(body, FreeFlight(), Gravity()), state, [0.0, 1.0])
    low = initial.from_omega(None, (0.0, 0.0, 0.0), x=(0.0, 0.0, 0.2), v=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="below the floor"):
        contact.simulate_bounces(scene, low, [0.0, 1.0])



@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"contact_tol": -1e-3}, "contact_tol must be a finite number > 0"),
        ({"contact_tol": float("nan")}, "contact_tol must be a finite number > 0"),
        ({"min_gap": -1.0}, "min_gap must be a finite number > 0"),
        ({"min_gap": 0.0}, "min_gap must be a finite number > 0"),
        ({"min_gap": float("inf")}, "min_gap must be a finite number > 0"),
        ({"rapid_bounces": 0}, "rapid_bounces must be an int >= 1"),
        ({"rapid_bounces": True}, "rapid_bounces must be an int >= 1"),
        ({"rapid_bounces": 2.5}, "rapid_bounces must be an int >= 1"),
        ({"max_bounces": -1}, "max_bounces must be an int >= 1"),
        ({"max_bounces": 0}, "max_bounces must be an int >= 1"),  # it recorded one bounce
    ],
)
def test_simulate_bounces_refuses_bad_resting_and_contact_settings(kwargs, message):
    """A negative contact_tol used to let the box fall through the floor, NaN to end in
    "failed" with no cause and min_gap < 0 in an internal diffrax error."""
    pts = contact.box_corners((1.0, 1.0, 1.0))
    body = RigidBody(inertia.box(1.0, 1.0, 1.0, 1.0), 1.0)
    scene = Scene(body, FreeFlight(), (Gravity(), contact.Floor(pts)))
    state = initial.from_omega(None, (0.0, 0.0, 0.0), x=(0.0, 0.0, 2.0), v=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match=message):
        contact.simulate_bounces(scene, state, [0.0, 1.0], **kwargs)


# --------------------------------------------------------------------------- bouncing ball


def ball_scene(a, e, g=9.81):
    body = RigidBody(inertia.sphere(1.0, a), 1.0)
    pts = jnp.tile(jnp.array([[0.0, 0.0, -a]]), (8, 1))  # 8 points: shares the compiled solve
    return Scene(body, FreeFlight(), (Gravity(g), contact.Floor(pts, 0.0, e, 0.0)))


@pytest.mark.parametrize("e", [1.0, 0.8])
def test_ball_bounce_times_follow_the_closed_form(e):
    a, h, g, vx = 0.1, 2.0, 9.81, 0.5
    scene = ball_scene(a, e, g)
    state = initial.from_omega(None, (0.0, 0.0, 0.0), x=(0.0, 0.0, h), v=(vx, 0.0, 0.0))
    run = contact.simulate_bounces(scene, state, jnp.linspace(0.0, 4.0, 101), max_bounces=6)
    b = run.bounces
    # t1 = sqrt(2 (h − a)/g), then intervals 2 e^k v1 / g with v1 = g t1
    t1 = math.sqrt(2 * (h - a) / g)
    v1 = g * t1
    k = np.arange(len(b["t"]))
    expect = t1 + np.concatenate([[0.0], np.cumsum(2 * v1 * e ** k[1:] / g)])
    n = min(len(expect), int(np.sum(expect < 4.0)))
    assert n >= 3
    # event located to ~1e-12 s; integration of a parabola by Tsit5 is exact to roundoff
    np.testing.assert_allclose(b["t"][:n], expect[:n], rtol=1e-9)
    np.testing.assert_allclose(b["un_after"] / b["un_before"], -e, rtol=1e-10)
    np.testing.assert_allclose(b["momentum_after"][:, :2], b["momentum_before"][:, :2], atol=1e-14)
    E = np.asarray(run.trajectory.energy)
    if e == 1.0:  # at rtol 1e-8 the parabola is integrated exactly; the floor lift is 1e-10
        assert np.max(np.abs(E / E[0] - 1)) < 1e-8
    ok = np.asarray(run.trajectory.ts) <= run.t_stop  # NaN after a max_bounces stop
    assert run.status == ("t_end" if e == 1.0 else "max_bounces") and ok.sum() > 50
    x = np.asarray(run.trajectory.x)[ok]
    np.testing.assert_allclose(x[:, 0], vx * np.asarray(run.trajectory.ts)[ok], rtol=1e-9)
    assert np.all(x[:, 2] >= a - 1e-9)


def test_ball_comes_to_rest_before_the_zeno_time():
    a, h, g, e = 0.1, 1.0, 9.81, 0.5
    scene = ball_scene(a, e, g)
    state = initial.from_omega(None, (0.0, 0.0, 0.0), x=(0.0, 0.0, h), v=(0.0, 0.0, 0.0))
    ts = jnp.linspace(0.0, 3.0, 101)
    run = contact.simulate_bounces(scene, state, ts, min_gap=1e-3, rapid_bounces=4)
    t1 = math.sqrt(2 * (h - a) / g)
    zeno = t1 + 2 * e * g * t1 / (g * (1 - e))  # t1 + Σ 2 e^k v1 / g
    assert run.status == "resting"
    last = run.bounces["t"][-1]
    # stops once 4 successive gaps are below 1e-3: the remaining gaps sum to < 2e-3
    assert zeno - 2e-3 < last < zeno
    x = np.asarray(run.trajectory.x)
    assert x[-1, 2] == pytest.approx(a, abs=1e-9)
    np.testing.assert_array_equal(np.asarray(run.trajectory.v)[-1], 0.0)
    assert run.dropped_energy < 0.5 * (g * 1e-3) ** 2  # below ½ (g · gap)² (unit mass)


def test_frictionless_elastic_impulses_stay_the_frictionless_formula():
    """μ = 0, e = 1: the impulse is P0 itself, whose energy change is rounding of either
    sign; moving it towards P0 divided 0 by 0 (NaN, and a failed 3-D bounce run)."""
    from jrigid import impacts

    rng = np.random.default_rng(5)
    m, moments, n = 1.0, jnp.array([0.4, 0.7, 0.9]), jnp.array([0.0, 0.0, 1.0])
    q = jax.vmap(quat.normalize)(jnp.asarray(rng.normal(size=(500, 4))))
    r, v = jnp.asarray(0.5 * rng.normal(size=(500, 3))), jnp.asarray(rng.normal(size=(500, 3)))
    w = jnp.asarray(2.0 * rng.normal(size=(500, 3)))
    P = jax.vmap(lambda *a: impacts.contact_impulse(m, moments, *a, n, 1.0, 0.0))(q, v, w, r)
    m_eff = jax.vmap(lambda q, r: impacts.effective_mass(m, moments, q, r, n))(q, r)
    un = (v + jax.vmap(lambda q, w, r: jnp.cross(quat.rotate(q, w), r))(q, w, r))[:, 2]
    expect = np.where(np.asarray(un) < 0, -2.0 * np.asarray(m_eff * un), 0.0)
    assert np.all(np.isfinite(np.asarray(P)))
    np.testing.assert_allclose(np.asarray(P)[:, 2], expect, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(np.asarray(P)[:, :2], 0.0)


def _box_scene(e, mu, size=(1.0, 0.6, 0.4), mass=2.0, g=9.81):
    from jrigid import impacts

    body = RigidBody(inertia.box(mass, *size), mass)
    floor = contact.Floor(impacts.box_corners(jnp.array(size)), restitution=e, friction=mu)
    return Scene(body, FreeFlight(), (Gravity(g), floor)), floor


@pytest.mark.parametrize("e, mu", [(0.5, 0.0), (1.0, 0.4)])
def test_a_box_landing_flat_bounces_straight_up_at_e_times_its_speed(e, mu):
    """Four corners touch at once. By symmetry the total impulse is vertical through the
    centre of mass: P = M (1 + e) |v|, v⁺ = e |v|, ω⁺ = 0, and every corner leaves at
    −e u_n. Impulses applied one corner at a time, each from the velocity the previous
    ones left, gave v⁺ = 0.26 |v| for e = 0.5 and a tumble of up to 5.7 rad/s."""
    g, mass, size, h = 9.81, 2.0, (1.0, 0.6, 0.4), 1.0
    scene, floor = _box_scene(e, mu, size, mass, g)
    state = initial.from_omega(None, (0.0, 0.0, 0.0), x=(0.0, 0.0, size[2] / 2 + h),
                               v=(0.0, 0.0, 0.0))
    t_hit = math.sqrt(2 * h / g)
    t_end = t_hit + 1e-9
    run = contact.simulate_bounces(scene, state, jnp.array([0.0, t_end]))
    b = run.bounces
    assert len(b["t"]) == 1 and b["impulses"][0] == 4
    v_hit = g * b["t"][0]  # at the contact, which is 1e-10 below the floor
    np.testing.assert_allclose(b["impulse_total"][0], [0.0, 0.0, mass * (1 + e) * v_hit],
                               rtol=1e-10, atol=1e-9)
    tr = run.trajectory
    v_end = e * v_hit - g * (t_end - b["t"][0])
    np.testing.assert_allclose(tr.v[-1], [0.0, 0.0, v_end], rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(tr.omega[-1], 0.0, atol=1e-9)
    u = np.asarray(contact.point_velocities(tr.q[-1], tr.omega[-1], tr.v[-1], floor.points))
    bottom = np.asarray(floor.points)[:, 2] < 0
    np.testing.assert_allclose(u[bottom, 2], v_end, rtol=1e-9, atol=1e-9)
    kinetic_after = np.sum(b["energy_after"][0][:2])
    assert kinetic_after == pytest.approx(0.5 * mass * (e * v_hit) ** 2, rel=1e-9, abs=1e-12)


def test_a_box_landing_on_an_edge_while_sliding():
    """Two corners touch at once while the box slides: each leaves at −e u_n (no
    friction), or the pair, with friction, ends within the friction cone and no energy
    is created."""
    scene0, floor = _box_scene(0.5, 0.0)
    q0 = quat.from_axis_angle(jnp.array([1.0, 0.0, 0.0]), jnp.array(0.4))
    r = np.asarray(quat.rotate(q0[None, :], floor.points))
    z0 = -np.min(r[:, 2]) + 0.3
    state = initial.from_omega(q0, (0.0, 0.0, 0.0), x=(0.0, 0.0, z0), v=(1.5, 0.0, 0.0))
    t_hit = math.sqrt(2 * 0.3 / 9.81)
    ts = jnp.array([0.0, t_hit + 1e-9])
    for mu in (0.0, 0.5):
        scene, floor = _box_scene(0.5, mu)
        run = contact.simulate_bounces(scene, state, ts)
        b = run.bounces
        assert len(b["t"]) == 1 and b["impulses"][0] == 2
        tr = run.trajectory
        u = np.asarray(contact.point_velocities(tr.q[-1], tr.omega[-1], tr.v[-1],
                                                floor.points))
        hit = np.argsort(np.asarray(quat.rotate(q0[None, :], floor.points))[:, 2])[:2]
        un_before = -9.81 * b["t"][0]  # the box falls without spin until the contact
        if mu == 0.0:  # both corners leave at −e u_n (then fall for 1e-9 s)
            np.testing.assert_allclose(b["un_after"] / b["un_before"], -0.5, rtol=1e-10)
            np.testing.assert_allclose(u[hit, 2], -0.5 * un_before, rtol=1e-7)
            assert u[hit[0], 2] == pytest.approx(u[hit[1], 2], rel=1e-12)
            np.testing.assert_allclose(b["impulse_total"][0][:2], 0.0, atol=1e-12)
        P = b["impulse_total"][0]
        assert np.hypot(P[0], P[1]) <= mu * P[2] * (1 + 1e-9)
        assert np.sum(b["energy_after"][0][:2]) <= np.sum(b["energy_before"][0][:2]) + 1e-12


def test_elastic_edge_landings_with_friction_never_create_energy():
    """A box of sides 1, 0.6, 0.4 tilted by 0.4 rad and dropped from rest lands on an edge
    (two corners at once) at its third bounce; with e = 1 and μ = 0.3 the simultaneous
    impulses raised the kinetic energy by 0.154 (2.4 %, Kane's paradox at several points);
    without friction the impact conserves it."""
    size = jnp.array([1.0, 0.6, 0.4])
    body = RigidBody(inertia.box(1.0, *size), 1.0)
    q0 = quat.from_axis_angle(jnp.array([1.0, 0.0, 0.0]), jnp.array(0.4))
    state = initial.from_omega(q0, (0.0, 0.0, 0.0), x=(0.0, 0.0, 1.5), v=(0.0, 0.0, 0.0))
    for mu in (0.3, 1.0, 0.0):
        floor = contact.Floor(impacts.box_corners(size), restitution=1.0, friction=mu)
        scene = Scene(body, FreeFlight(), (Gravity(), floor))
        b = contact.simulate_bounces(scene, state, jnp.linspace(0.0, 2.0, 41)).bounces
        assert np.max(b["impulses"]) == 2  # edge landings
        gain = np.sum(b["energy_after"][:, :2], 1) - np.sum(b["energy_before"][:, :2], 1)
        assert np.all(gain <= 1e-9 * np.sum(b["energy_before"][:, :2], 1)), (mu, gain)
        if mu == 0.0:
            np.testing.assert_allclose(gain, 0.0, atol=1e-11)


def test_bounce_trajectories_count_their_steps_as_simulate_does():
    """Only num_steps was there; Trajectory documents the accepted and rejected counts."""
    scene = ball_scene(0.5, 0.5, 9.81)
    state = initial.from_omega(None, (0.0, 0.0, 0.0), x=(0.0, 0.0, 2.0), v=(0.0, 0.0, 0.0))
    run = contact.simulate_bounces(scene, state, jnp.linspace(0.0, 1.0, 5))
    stats = {k: int(v) for k, v in run.trajectory.stats.items()}
    assert stats["num_steps"] == run.num_steps > 0
    assert stats["num_accepted_steps"] + stats["num_rejected_steps"] == stats["num_steps"]


def test_a_body_still_sliding_when_contacts_pile_up_is_held_still_with_a_warning():
    """A ball sliding at 3 m/s without friction stopped as 'resting' (success) with its
    4.5 J of horizontal kinetic energy dropped silently; one dropped straight down keeps
    the quiet stop (the energy left is at rounding level)."""
    scene = ball_scene(0.5, 0.5, 9.81)
    sliding = initial.from_omega(None, (0.0, 0.0, 0.0), x=(0.0, 0.0, 2.0), v=(3.0, 0.0, 0.0))
    with pytest.warns(contact.RestingWarning, match="sliding, rolling or tipping"):
        run = contact.simulate_bounces(scene, sliding, jnp.linspace(0.0, 3.0, 31))
    assert run.status == "resting"
    assert run.dropped_energy == pytest.approx(0.5 * float(scene.body.mass) * 9.0, rel=1e-6)
    still = initial.from_omega(None, (0.0, 0.0, 0.0), x=(0.0, 0.0, 2.0), v=(0.0, 0.0, 0.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error", contact.RestingWarning)
        assert contact.simulate_bounces(scene, still, jnp.linspace(0.0, 3.0, 31)).status == \
            "resting"


def test_tracing_simulate_bounces_is_refused_with_the_remedy():
    """jax.grad through it ended in a ConcretizationTypeError from inside."""
    scene = ball_scene(0.5, 0.5, 9.81)

    def height(z):
        state = initial.from_omega(None, (0.0, 0.0, 0.0), x=jnp.stack([0.0, 0.0, z]),
                                   v=(0.0, 0.0, 0.0))
        return contact.simulate_bounces(scene, state, jnp.linspace(0.0, 1.0, 3)).trajectory.x[-1, 2]

    with pytest.raises(TypeError, match="cannot be traced.*jrigid.impacts"):
        jax.grad(height)(2.0)


@pytest.mark.parametrize("change, message", [
    (dict(restitution=2.0), "restitution must be in"),
    (dict(friction=-1.0), "friction must be finite and >= 0"),
    (dict(mass=0.0), "mass must be finite and > 0"),
    (dict(normal=jnp.zeros(3)), "normal must be finite and non-zero"),
    (dict(r=jnp.zeros(4)), r"r must have shape \(3,\)"),
    (dict(q=jnp.ones((2, 4))), r"q must have shape \(4,\)"),
])
def test_impact_functions_refuse_bad_arguments(change, message):
    """They took any shape and any value: an r of four entries, e = 2 (an impact that
    doubles the energy), μ < 0 (a cone of negative width), a zero normal (no impulse)."""
    args = dict(mass=1.0, moments=jnp.array([1.0, 2.0, 2.5]), q=jnp.array([1.0, 0, 0, 0]),
                v=jnp.array([0.0, 0.0, -1.0]), omega=jnp.zeros(3), r=jnp.array([0.0, 0, -1]),
                normal=jnp.array([0.0, 0, 1]), restitution=0.5, friction=0.3)
    np.testing.assert_allclose(impacts.contact_impulse(**args), [0.0, 0.0, 1.5], atol=1e-12)
    with pytest.raises(ValueError, match=message):
        impacts.contact_impulse(**{**args, **change})
