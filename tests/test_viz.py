"""Tests of jrigid.viz: meshes, projection and painter's order, series, plots, animations."""

import subprocess
import sys
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from PIL import Image
from scipy.spatial.transform import Rotation

from jrigid import viz
from jrigid.viz import render, shapes

# --------------------------------------------------------------------------- helpers


def _face_areas_normals(mesh):
    """Vector area of each planar face (sum of cross products), independent of mesh.normals."""
    P = mesh.vertices[mesh.faces]
    nxt = np.roll(P, -1, axis=1)
    return 0.5 * np.sum(np.cross(P, nxt), axis=1)


def _volume(mesh):
    """Divergence theorem: V = (1/3) Σ (x_f · A_f) over planar faces."""
    A = _face_areas_normals(mesh)
    return np.sum(np.sum(mesh.vertices[mesh.faces[:, 0]] * A, axis=-1)) / 3.0


def _symmetric_top(I1=1.0, I3=1.9, w3=3.0, theta=0.25, T=200, t_end=4.0):
    """Exact torque-free symmetric top with L along z, built with scipy (ZXZ intrinsic)."""
    L = I3 * w3 / np.cos(theta)
    phid, psid = L / I1, w3 * (I1 - I3) / I1
    ts = np.linspace(0.0, t_end, T)
    ang = np.stack([phid * ts, np.full_like(ts, theta), psid * ts], axis=-1)
    q = Rotation.from_euler("ZXZ", ang).as_quat(scalar_first=True)
    ph, th, ps = ang.T
    omega = np.stack(
        [
            phid * np.sin(th) * np.sin(ps),
            phid * np.sin(th) * np.cos(ps),
            phid * np.cos(th) + psid,
        ],
        axis=-1,
    )
    data = {"ts": ts, "q": q, "omega": omega, "moments": np.array([I1, I1, I3])}
    return data, dict(L=L, phid=phid, psid=psid, theta=theta)


def _steady(rate=2.0, axis=(0.0, 0.0, 1.0), T=50, t_end=2.0):
    ts = np.linspace(0.0, t_end, T)
    axis = np.asarray(axis) / np.linalg.norm(axis)
    q = Rotation.from_rotvec(ts[:, None] * rate * axis).as_quat(scalar_first=True)
    return {"ts": ts, "q": q, "omega": np.tile(rate * axis, (T, 1))}


def _pixels(fig):
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(float)


def _assert_image(path):
    assert path.exists() and path.stat().st_size > 2000
    img = np.asarray(Image.open(path).convert("RGB"), dtype=float)
    assert img.std() > 5.0  # not a blank canvas


MESHES = {
    "box": lambda: shapes.box(1.0, 0.6, 0.3),
    "ellipsoid": lambda: shapes.ellipsoid(0.6, 0.4, 0.25),
    "disk": lambda: shapes.disk(1.0, 0.1),
    "rod": lambda: shapes.rod(1.5),
    "t_handle": lambda: shapes.t_handle(),
}

# --------------------------------------------------------------------------- shapes


@pytest.mark.parametrize("name", list(MESHES))
def test_mesh_is_closed_with_outward_unit_normals(name):
    mesh = MESHES[name]()
    A = _face_areas_normals(mesh)
    area = np.linalg.norm(A, axis=-1)
    assert np.all(area > 0)
    # closed surface: the vector areas cancel
    assert np.allclose(A.sum(axis=0), 0.0, atol=1e-12 * area.sum())
    # stored normals are unit, parallel to the face's vector area, and outward (V > 0)
    assert np.allclose(np.linalg.norm(mesh.normals, axis=-1), 1.0)
    cos = np.sum(mesh.normals * A, axis=-1) / area
    assert np.all(cos > 0.99)
    assert _volume(mesh) > 0
    assert mesh.colors.shape == (len(mesh.faces), 3)
    assert np.all((mesh.colors >= 0) & (mesh.colors <= 1))


def test_box_volume_and_extent_match_side_lengths():
    mesh = shapes.box(1.0, 0.6, 0.3)
    assert _volume(mesh) == pytest.approx(1.0 * 0.6 * 0.3, rel=1e-12)
    assert np.allclose(mesh.vertices.max(axis=0), [0.5, 0.3, 0.15])
    assert np.allclose(mesh.vertices.min(axis=0), [-0.5, -0.3, -0.15])


@pytest.mark.parametrize("n", [8, 24])
def test_cylinder_volume_is_the_prism_volume(n):
    r, h = 0.7, 0.2
    mesh = shapes.cylinder(r, h, n=n)
    assert _volume(mesh) == pytest.approx(0.5 * n * r * r * np.sin(2 * np.pi / n) * h, rel=1e-12)


def test_ellipsoid_is_inscribed_and_close():
    a, b, c = 0.6, 0.4, 0.25
    mesh = shapes.ellipsoid(a, b, c, n_lat=16, n_lon=32)
    v = _volume(mesh)
    exact = 4 / 3 * np.pi * a * b * c
    assert 0.95 * exact < v < exact
    r = np.sum((mesh.vertices / [a, b, c]) ** 2, axis=-1)
    assert np.allclose(r, 1.0)


def test_t_handle_centre_of_mass_at_origin():
    mesh = shapes.t_handle()
    # volume-weighted centroid of the (non-overlapping) parts, by the divergence theorem
    A = _face_areas_normals(mesh)
    x = mesh.vertices[mesh.faces]
    # ∫ x dV = ½ Σ_f ∫_f |x|² n dA; with the face centroid quadrature exact for linear
    # integrands only, use the tetrahedra from the origin instead:
    tets = []
    for k in range(1, 3):
        p0, p1, p2 = x[:, 0], x[:, k], x[:, k + 1]
        vol = np.sum(p0 * np.cross(p1, p2), axis=-1) / 6.0
        tets.append((vol, (p0 + p1 + p2) / 4.0))
    V = sum(v.sum() for v, _ in tets)
    com = sum((v[:, None] * c).sum(axis=0) for v, c in tets) / V
    assert np.allclose(com, 0.0, atol=1e-12)
    assert V == pytest.approx(_volume(mesh), rel=1e-12)
    assert A.shape[0] == len(mesh.faces)


# --------------------------------------------------------------------------- projection


@settings(max_examples=25, deadline=None)
@given(
    elev=st.floats(-89.0, 89.0) | st.sampled_from([90.0, -90.0, 0.0]),
    azim=st.floats(-360.0, 360.0),
    seed=st.integers(0, 2**32 - 1),
)
def test_orthographic_projection_matches_camera_axes(elev, azim, seed):
    cam = render.Camera(elev=elev, azim=azim)
    p = np.random.default_rng(seed).normal(size=(7, 3))
    uv, depth = render.project(p, cam)
    # independent camera frame: toward-eye d, screen right r, screen up u
    e, a = np.radians(elev), np.radians(azim)
    d = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    r = np.cross(-d, cam.up)
    r /= np.linalg.norm(r)
    u = np.cross(r, -d)
    assert np.allclose(uv[:, 0], p @ r, atol=1e-9)
    assert np.allclose(uv[:, 1], p @ u, atol=1e-9)
    # depth grows away from the viewer, up to a constant
    assert np.allclose(np.diff(depth), -np.diff(p @ d), atol=1e-9)
    if abs(elev) < 89.0:  # world z points up on the screen
        assert u[2] > 0


def test_perspective_projection_shrinks_far_points():
    cam = render.Camera(elev=0.0, azim=0.0, distance=5.0, fov=40.0)
    near = np.array([[1.0, 0.5, 0.5]])
    far = np.array([[-1.0, 0.5, 0.5]])
    (uv_n, d_n), (uv_f, d_f) = render.project(near, cam), render.project(far, cam)
    assert d_n[0] == pytest.approx(4.0) and d_f[0] == pytest.approx(6.0)
    # pinhole: screen offset ∝ 1/depth; scaled to world units at the target distance 5
    assert np.allclose(uv_n[0], [0.5 * 5 / 4, 0.5 * 5 / 4])
    assert np.allclose(uv_f[0], [0.5 * 5 / 6, 0.5 * 5 / 6])


def test_back_faces_are_culled():
    mesh = shapes.box(1.0, 1.0, 1.0, n=3)
    cam = render.Camera(elev=0.0, azim=0.0)  # looking along -x: only the +x side faces us
    polys = render.mesh_polygons(mesh, np.eye(4), cam)
    assert len(polys.depth) == 9
    keep = mesh.normals[:, 0] > 0.5
    assert np.allclose(np.sort(polys.depth), np.sort(render.project(mesh.centers[keep], cam)[1]))


def test_body_transform_places_vertices_like_scipy():
    rng = np.random.default_rng(1)
    rot = Rotation.random(random_state=rng)
    q = rot.as_quat(scalar_first=True)
    pos = np.array([0.3, -0.2, 1.0])
    T = render.body_transform(q, pos)
    assert np.allclose(T[:3, :3], rot.as_matrix(), atol=1e-12)
    assert np.allclose(T[:3, 3], pos)
    batch = render.body_transform(np.stack([q, q]))
    assert batch.shape == (2, 4, 4)


def _scene_pixels(arrow_x, order):
    """Render a unit cube and a red bar at x = arrow_x, viewed from +x; return pixels."""
    cam = render.Camera(elev=0.0, azim=0.0)
    cube = render.mesh_polygons(shapes.box(1.0, 1.0, 1.0, color="#2060ff"), np.eye(4), cam)
    bar = render.arrow_polygons(
        [arrow_x, -0.9, 0.0], [0.0, 1.8, 0.0], cam, "#ff0000", width=0.2, head_length=0.05
    )
    parts = (cube, bar) if order == "cube first" else (bar, cube)
    fig = viz.new_figure(figsize=(3, 3), dpi=100, layout=None)
    ax = fig.add_axes((0, 0, 1, 1))
    render.setup_axes(ax, 1.2)
    render.draw_polygons(ax, render.combine(*parts))
    px = _pixels(fig)
    h = px.shape[0]

    def at(u, v):
        x, y = ax.transData.transform((u, v))
        return px[int(round(h - y)), int(round(x))]

    return at


@pytest.mark.parametrize("order", ["cube first", "bar first"])
def test_painters_algorithm_hides_what_is_behind(order):
    red = np.array([255.0, 0.0, 0.0])
    behind = _scene_pixels(-1.5, order)  # bar behind the cube
    assert np.linalg.norm(behind(0.0, 0.0) - red) > 100  # the cube hides it
    assert np.linalg.norm(behind(0.75, 0.0) - red) < 40  # visible beside the cube
    front = _scene_pixels(1.5, order)  # bar in front of the cube
    assert np.linalg.norm(front(0.0, 0.0) - red) < 40


# --------------------------------------------------------------------------- data


def test_series_derives_space_vectors_momentum_and_energy():
    data, _ = _symmetric_top()
    s = viz.as_series(data)
    R = Rotation.from_quat(data["q"], scalar_first=True)
    assert np.allclose(s.R, R.as_matrix(), atol=1e-12)
    assert np.allclose(s.omega_space, R.apply(data["omega"]), atol=1e-12)
    L_body = data["omega"] * data["moments"]
    assert np.allclose(s.L, L_body)
    assert np.allclose(s.L_space, R.apply(L_body), atol=1e-12)
    assert np.allclose(s.kinetic_energy, 0.5 * np.sum(L_body * data["omega"], axis=-1))
    assert np.allclose(s.q_norm_error, 0.0, atol=1e-15)


def test_series_from_space_vectors_and_errors():
    data = _steady(axis=(1.0, 2.0, 0.5))
    R = Rotation.from_quat(data["q"], scalar_first=True)
    s = viz.as_series({"q": data["q"], "omega_space": R.apply(data["omega"])})
    assert np.allclose(s.omega, data["omega"], atol=1e-12)
    assert np.allclose(s.ts, np.arange(len(data["q"])))
    with pytest.raises(ValueError, match="need quaternions"):
        viz.as_series({"omega": data["omega"]})
    with pytest.raises(ValueError, match="shape"):
        viz.as_series({"q": data["q"], "omega": data["omega"][:3]})
    with pytest.raises(ValueError, match="neither an energy nor L"):
        viz.plot_invariants({"q": data["q"]})


def test_resample_uses_slerp_and_is_exact_at_samples():
    rate, axis = 1.3, np.array([1.0, -1.0, 2.0]) / np.sqrt(6.0)
    data = _steady(rate=rate, axis=axis, T=11, t_end=2.0)
    times = np.linspace(0.0, 2.0, 37)
    s = viz.resample(data, times)
    expected = Rotation.from_rotvec(times[:, None] * rate * axis)
    got = Rotation.from_quat(s.q, scalar_first=True)
    assert np.allclose((expected.inv() * got).magnitude(), 0.0, atol=1e-12)
    at_samples = viz.resample(data, data["ts"])
    assert np.allclose(np.abs(np.sum(at_samples.q * data["q"], axis=-1)), 1.0, atol=1e-12)


def test_resample_refuses_coarse_data_and_out_of_range_times():
    data = _steady(rate=40.0, T=5, t_end=1.0)  # 10 rad between samples
    with pytest.raises(ValueError, match="too coarse"):
        viz.resample(data, np.linspace(0, 1, 9))
    with pytest.raises(ValueError, match="leave the data"):
        viz.resample(_steady(), np.linspace(0, 3, 9))


# --------------------------------------------------------------------------- angles


@pytest.mark.parametrize("theta", [0.05, 0.25, 1.0])
def test_euler_about_recovers_symmetric_top_rates(theta):
    data, exact = _symmetric_top(theta=theta)
    s = viz.as_series(data)
    ang = viz.euler_about(data["q"], s.L_space, axis=2)
    assert np.allclose(ang[:, 1], theta, atol=1e-10)
    assert viz.fit_rate(data["ts"], ang[:, 0]) == pytest.approx(exact["phid"], rel=1e-10)
    assert viz.fit_rate(data["ts"], ang[:, 2]) == pytest.approx(exact["psid"], rel=1e-10)


def test_euler_about_follows_any_body_axis():
    # the same motion with the symmetry axis relabelled as body x: R' = R P
    data, exact = _symmetric_top(theta=0.3)
    P = Rotation.from_matrix(np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]))
    q = (Rotation.from_quat(data["q"], scalar_first=True) * P).as_quat(scalar_first=True)
    ang = viz.euler_about(q, [0.0, 0.0, exact["L"]], axis=0)
    assert np.allclose(ang[:, 1], 0.3, atol=1e-10)
    assert viz.fit_rate(data["ts"], ang[:, 0]) == pytest.approx(exact["phid"], rel=1e-10)
    with pytest.raises(ValueError, match="axis"):
        viz.euler_about(q, [0.0, 0.0, 1.0], axis=3)


def test_fit_rate_is_the_least_squares_slope():
    ts = np.linspace(0, 1, 50)
    assert viz.fit_rate(ts, 3.0 * ts + 0.1 * np.sin(40 * ts) * 0 + 2.0) == pytest.approx(3.0)


# --------------------------------------------------------------------------- pictures


PLOTS = {
    "omega_body": lambda d: viz.plot_omega(d),
    "omega_space": lambda d: viz.plot_omega(d, frame="space"),
    "invariants": lambda d: viz.plot_invariants(d),
    "q_norm": lambda d: viz.plot_q_norm(d),
    "euler": lambda d: viz.plot_euler_angles(d, seq="ZXZ"),
    "euler_xyz": lambda d: viz.plot_euler_angles(d, seq="xyz"),
    "precession": lambda d: viz.plot_precession_nutation(d),
    "overview": lambda d: viz.plot_overview(d),
    "views": lambda d: viz.space_body_views(d, shapes.disk(1.0, 0.1), trail=20),
    "views_perspective": lambda d: viz.space_body_views(
        d, shapes.box(1.0, 0.6, 0.3), camera=render.Camera(distance=6.0)
    ),
}


@pytest.mark.parametrize("name", list(PLOTS))
def test_plot_writes_an_image(name, tmp_path):
    data, _ = _symmetric_top(T=60)
    fig = PLOTS[name](data)
    path = viz.save(fig, tmp_path / f"{name}.png")
    _assert_image(path)
    for ax in fig.axes:  # every time axis says its unit
        label = ax.get_xlabel()
        assert label in ("", "t [s]") or "[" in label, (name, label)
    if name.startswith("omega"):
        assert fig.axes[0].get_ylabel() == "ω [rad/s]"


def test_saved_images_are_readable_at_page_width(tmp_path):
    """Raster images are at least MIN_WIDTH_PX wide whatever dpi is asked; vector kept."""
    from jrigid.report import Report

    fig = viz.plot_omega(_steady(), ax=None)  # 6 in wide at 100 dpi: 600 px as drawn
    for path, dpi in ((tmp_path / "low.png", 60), (tmp_path / "default.png", None)):
        viz.save(fig, path, dpi=dpi)
        assert Image.open(path).size[0] >= viz.MIN_WIDTH_PX
    viz.save(fig, tmp_path / "high.png", dpi=300)  # a higher dpi is kept
    assert Image.open(tmp_path / "high.png").size[0] == 1800
    viz.save(fig, tmp_path / "as_asked.png", dpi=50, min_width=0)
    assert Image.open(tmp_path / "as_asked.png").size[0] == 300
    assert viz.save(fig, tmp_path / "v.svg", dpi=60).read_text().lstrip().startswith("<?xml")
    path = Report(tmp_path / "report").figure("omega", fig, dpi=60)
    assert Image.open(path).size[0] >= viz.MIN_WIDTH_PX


def test_plot_estimates_shows_standardised_errors(tmp_path):
    fig = viz.plot_estimates(["a", "b"], [1.1, 2.0], [1.0, 2.2], [0.05, 0.1])
    points = fig.axes[0].containers[0].lines[0].get_ydata()  # the error-bar markers
    np.testing.assert_allclose(points, [2.0, -2.0])
    _assert_image(viz.save(fig, tmp_path / "estimates.png"))


@pytest.mark.parametrize("name", list(MESHES))
def test_body_still_writes_an_image(name, tmp_path):
    q = Rotation.from_euler("zxz", [0.3, 0.4, 0.5]).as_quat(scalar_first=True)
    fig = viz.body_still(MESHES[name](), q, omega=[0.1, 0.2, 1.0], L=[0.0, 0.3, 1.0], title=name)
    _assert_image(viz.save(fig, tmp_path / f"{name}.png"))


def test_plot_draws_into_given_axes():
    fig = viz.new_figure()
    ax = fig.add_subplot(1, 1, 1)
    out = viz.plot_omega(_steady(), ax=ax)
    assert out is fig
    assert len(ax.lines) == 3
    assert np.allclose(ax.lines[2].get_ydata(), 2.0)


def test_dual_view_redraws_frames():
    data, _ = _symmetric_top(T=30)
    view = viz.DualView(data, shapes.ellipsoid(0.6, 0.4, 0.25), trail=5)
    a = _pixels(view.draw(3))
    b = _pixels(view.draw(20))
    assert a.shape == b.shape and np.abs(a - b).mean() > 0.1
    assert view.time_text.get_text() == f"t = {data['ts'][20]:.3g}"


def test_animation_writes_a_gif_with_the_requested_frames(tmp_path):
    data, _ = _symmetric_top(T=200, t_end=1.0)
    paths = viz.animate(data, shapes.disk(1.0, 0.1), tmp_path / "a.gif", n_frames=12, fps=10,
                        size_px=(200, 100), dpi=50, mp4=False)  # fmt: skip
    assert paths == [tmp_path / "a.gif"]
    with Image.open(paths[0]) as im:
        assert im.n_frames == 12
        assert im.size == (200, 100)
        assert im.info["duration"] == 100


def test_animation_warns_about_aliasing(tmp_path):
    data = _steady(rate=30.0, T=400, t_end=2.0)  # 60 rad in 2 s
    with pytest.warns(viz.AliasingWarning, match="aliasing"):
        viz.animate(data, shapes.box(1, 0.5, 0.2), tmp_path / "b.gif", n_frames=5,
                    size_px=(100, 50), dpi=50)  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error", viz.AliasingWarning)
        viz.animate(data, shapes.box(1, 0.5, 0.2), tmp_path / "c.gif", n_frames=30,
                    t_span=(0.0, 0.25), size_px=(100, 50), dpi=50)  # fmt: skip


def test_mp4_needs_ffmpeg(tmp_path):
    data = _steady()
    if viz.ffmpeg_available():
        paths = viz.animate(data, shapes.rod(1.0), tmp_path / "m.mp4", n_frames=4)
        assert paths[0].stat().st_size > 0
    else:
        with pytest.raises(ValueError, match="ffmpeg"):
            viz.animate(data, shapes.rod(1.0), tmp_path / "m.mp4", n_frames=4)
    with pytest.raises(ValueError, match=".gif or .mp4"):
        viz.animate(data, shapes.rod(1.0), tmp_path / "m.avi", n_frames=4)


def test_trajectory_from_simulate_is_drawn(tmp_path):
    jnp = pytest.importorskip("jax.numpy")
    from jrigid import inertia, initial
    from jrigid.body import RigidBody
    from jrigid.integrate import simulate
    from jrigid.scene import Scene

    moments = inertia.box(1.0, 1.0, 0.6, 0.3)
    # 401 samples, as `jrigid demo --quick`: the compiled solve is shared within a session
    ts = jnp.linspace(0.0, 2.0, 401)
    traj = simulate(
        Scene(RigidBody(moments)), initial.tilted(1, 0.05, 3.0), ts, rtol=1e-8, atol=1e-10
    )
    s = viz.as_series(traj)  # Trajectory names: norm_error, scene.body.moments
    assert np.allclose(s.moments, np.asarray(moments))
    assert np.allclose(s.L, np.asarray(traj.L))
    assert np.allclose(s.q_norm_error, np.asarray(traj.norm_error))
    assert np.allclose(s.energy, np.asarray(traj.energy))
    _assert_image(viz.save(viz.plot_overview(traj, axis=1), tmp_path / "o.png"))
    _assert_image(
        viz.save(viz.space_body_views(traj, shapes.box(1.0, 0.6, 0.3)), tmp_path / "v.png")
    )


def test_drawing_works_in_float32(float32, tmp_path):
    data, exact = _symmetric_top(T=40)
    s = viz.as_series(data)
    assert s.L_space.dtype == np.float64  # numpy series, computed in float32
    assert np.allclose(s.L_space[:, 2], exact["L"], rtol=1e-5)
    _assert_image(viz.save(viz.space_body_views(data, shapes.disk(1.0, 0.1)), tmp_path / "v.png"))


def test_import_jrigid_does_not_import_matplotlib_and_viz_leaves_pyplot_alone():
    code = (
        "import sys, jrigid, jrigid.cli, jrigid.registry, jrigid.report\n"
        "assert 'matplotlib' not in sys.modules, 'matplotlib imported by jrigid'\n"
        "import jrigid.viz\n"
        "assert 'matplotlib.pyplot' not in sys.modules, 'pyplot imported by jrigid.viz'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


def test_stability_drawings_need_one_value_per_direction():
    """Too many values were drawn from the first N, too few ended in an IndexError, an
    (N, 1) column in matplotlib's shape message."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jrigid import stability
    from jrigid.viz import stability as vs

    dirs = np.asarray(stability.fibonacci_sphere(50))
    moments = np.array([1.0, 2.0, 3.0])
    fig = plt.figure()
    try:
        ax_map = fig.add_subplot(1, 2, 1, projection="mollweide")
        ax_globe = fig.add_subplot(1, 2, 2)
        vs.draw_map(ax_map, dirs, dirs[:, 0], moments, resolution=8)
        vs.draw_globe(ax_globe, dirs, dirs[:, 0], moments, resolution=8)
        for bad in (np.ones(60), np.ones(40), np.ones((50, 1))):
            for draw, ax in ((vs.draw_map, ax_map), (vs.draw_globe, ax_globe)):
                with pytest.raises(ValueError, match=r"values must have shape \(N,\) = \(50,\)"):
                    draw(ax, dirs, bad, moments, resolution=8)
    finally:
        plt.close(fig)


def test_samples_that_are_not_finite_are_left_out_with_a_warning():
    """One NaN row made np.unwrap blank every later Euler angle; a failed solve's NaN tail
    gave a misleading 'axis vector is zero' in the precession plot and an internal JAX
    error in the views; a zero quaternion in body_still the same."""
    data, _ = _symmetric_top()
    clean = viz.plot_euler_angles(data)
    broken = {k: np.array(v, float).copy() for k, v in data.items()}
    broken["q"][50] = np.nan
    with pytest.warns(viz.DroppedSamplesWarning, match="1 of 200 samples"):
        fig = viz.plot_euler_angles(broken)
    for line, ref in zip(fig.axes[0].lines, clean.axes[0].lines, strict=True):
        y = line.get_ydata()
        assert y.shape == (199,) and np.all(np.isfinite(y))
        np.testing.assert_allclose(y, np.delete(ref.get_ydata(), 50), atol=1e-9)
    tail = {k: np.array(v, float).copy() for k, v in data.items()}
    tail["q"][120:], tail["omega"][120:], tail["ts"][150:] = np.nan, np.nan, np.nan
    with pytest.warns(viz.DroppedSamplesWarning, match="80 of 200 samples"):
        viz.plot_precession_nutation(tail)
    with pytest.warns(viz.DroppedSamplesWarning):
        viz.space_body_views(tail, shapes.box(1.0, 0.6, 0.3))
    with pytest.raises(ValueError, match="no usable sample"):
        viz.plot_euler_angles({"ts": np.zeros(2), "q": np.full((2, 4), np.nan)})
    with pytest.raises(ValueError, match="zero quaternion"):
        viz.body_still(shapes.box(1.0, 0.5, 0.2), np.zeros(4))
