"""The friction of the projectile's sphere contact as a term (rve.model.terms.sphere_friction
in a SphereContactTerm): a sphere dragged over a straight fibril sticks at the tangential
stiffness, slides at mu N and dissipates mu N times the slip; spinning in place loads the
contact, rolling does not; the stick state is carried across pair rebuilds and on to the
next element; the history round-trips by pair key."""
import numpy as np
import pytest

from rve.fem.mesh import fibril_mesh, straight_fibril
from rve.model.terms.projectile_contact import SphereContactTerm

RP, RF, PSTAR, DELTA = 2.0, 0.2, 20.0, 0.01    # radii, line penalty, overlap
FAR = [0.0, 0.0, 100.0]


def _setup(mu, ratio):
    mesh = fibril_mesh([straight_fibril([-5, 0, 0], [5, 0, 0], RF)], 10, 1)   # elements of 1 mm
    term = SphereContactTerm(mesh, RP, PSTAR, margin=0.3, friction=(mu, ratio))
    return term, mesh.X0[:, :3].copy()


def _frames(theta=0.0):
    """The projectile's end frames (d1 = -e_y, d2 = e_x: d1 x d2 = e_z), the first rotated by
    theta about e_y."""
    c, s = np.cos(theta), np.sin(theta)
    Ry = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    f = np.array([[[0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]] * 2)
    f[0] = f[0] @ Ry.T
    return f


def _centres(x):
    return np.array([[x, 0.0, RP + RF - DELTA], FAR])


def _step(term, r, x, frames, rebuild=False):
    """Forces at the sphere's position ``x``, then commit (an accepted step)."""
    c = _centres(x)
    if rebuild:
        term.rebuild(c, r, frames)
    f = term.forces_on_centres(c, r, frames)[0]
    term.friction.commit(term.local(c, r, frames))
    return f


def test_drag_sticks_slides_and_dissipates_mu_N_slip():
    mu, ratio = 0.3, 1.0
    term, r = _setup(mu, ratio)
    fr = _frames()
    x0 = 0.5                                  # over the centre of element 5: one pair in contact
    term.rebuild(_centres(x0), r, fr)
    N = PSTAR * 1.0 * DELTA                    # k g, k = P* l_e
    kT = ratio * PSTAR * 1.0
    lim = mu * N
    us = np.linspace(0.0, 0.02, 41)
    fx = np.array([_step(term, r, x0 + u, fr)[0] for u in us])
    assert np.count_nonzero(term.gaps(_centres(x0), r) > 0) == 1
    stick = us < lim / kT
    np.testing.assert_allclose(fx[stick], -kT * us[stick], rtol=1e-9, atol=1e-15)   # the elastic branch
    np.testing.assert_allclose(fx[~stick], -lim, rtol=1e-9)                           # Coulomb
    np.testing.assert_allclose(term.friction.dissipated, lim * (us[-1] - lim / kT), rtol=1e-9)
    # back by 2 mu N / kT: the force reverses along the elastic branch (the hysteresis)
    back = us[-1] - np.linspace(0.0, 2 * lim / kT, 11)[1:]
    fb = np.array([_step(term, r, x0 + u, fr)[0] for u in back])
    np.testing.assert_allclose(fb, -lim + kT * (us[-1] - back), rtol=1e-9, atol=1e-12)


def test_spinning_in_place_loads_the_contact_and_rolling_does_not():
    """The projectile's material point moves with its directors: a spin theta about e_y at a
    fixed centre slides the contact point by R_p sin(theta) (stick: the force kT R_p sin
    theta), rolling (the centre moved on by R_p theta) moves it by R_p (theta - sin theta)."""
    mu, ratio = 1.0, 0.1
    term, r = _setup(mu, ratio)
    x0 = 0.5
    term.rebuild(_centres(x0), r, _frames())
    _step(term, r, x0, _frames())
    kT = ratio * PSTAR
    th = 2e-3
    c = _centres(x0)
    f = term.forces_on_centres(c, r, _frames(th))[0]
    st = term.friction.state(term.local(c, r, _frames(th)))
    assert st.stick.sum() == 1
    # the contact point (0, 0, -R_p) below the centre moves to -R_p sin(theta) along x: the
    # friction force on the sphere points back, +kT R_p sin(theta)
    np.testing.assert_allclose(f[0], kT * RP * np.sin(th), rtol=1e-6)
    c = _centres(x0 + RP * th)                   # rolling towards +x (the point below stays)
    f = term.forces_on_centres(c, r, _frames(th))[0]
    assert abs(f[0]) <= kT * RP * th ** 3


@pytest.mark.parametrize("rebuild", [False, True])
def test_stick_state_carried_across_rebuilds_and_on_to_the_next_element(rebuild):
    """Dragged in stick from the middle of element 5 to that of element 6 (the pair table
    rebuilt at every step or never): at the end the one pair in contact, a new one, carries
    the whole elastic gap, kT U, not the part since it came into contact."""
    mu, ratio = 2.0, 0.001
    term, r = _setup(mu, ratio)
    fr = _frames()
    x0, U = 0.5, 1.0
    term.rebuild(_centres(x0), r, fr)
    for u in np.linspace(0.0, U, 51):
        f = _step(term, r, x0 + u, fr, rebuild=rebuild)
    kT = ratio * PSTAR
    on = term.gaps(_centres(x0 + U), r) > 0
    assert on.sum() == 1 and term.element[on][0] == 6
    assert term.friction.last.stick.sum() == 1 and term.friction.dissipated == 0.0
    np.testing.assert_allclose(f[0], -kT * U, rtol=2e-3)


def test_history_round_trips_by_pair_key():
    term, r = _setup(0.3, 1.0)
    fr = _frames()
    term.rebuild(_centres(0.5), r, fr)
    for u in np.linspace(0.0, 0.01, 5):
        _step(term, r, 0.5 + u, fr)
    rec = term.friction.record()
    F0 = term.forms(_centres(0.52), r, False, fr)[1]
    other, _ = _setup(0.3, 1.0)
    other.rebuild(_centres(0.51), r, fr)
    hit = other.friction.seed(rec)
    assert hit.all() and other.friction.dissipated == term.friction.dissipated > 0
    np.testing.assert_array_equal(other.forms(_centres(0.52), r, False, fr)[1], F0)
