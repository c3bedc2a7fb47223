"""The yt and sarracen bridges, with the real packages (installed into the test environment by
`cargo xtask test`): the particles arrive in code units, and the SPH field is the one the
package computes from the same arrays, and the one sarracen computes."""

import logging

import numpy as np
import pytest

import aarbf


def sph_particles(n=3000, seed=4):
    """Particles as an SPH code leaves them: h from the volume, equal masses, rho perturbed."""
    rng = np.random.default_rng(seed)
    pos = rng.random((n, 3))
    m = np.full(n, 1.0 / n)
    rho = 1.0 + 0.1 * (rng.random(n) - 0.5)
    h = 1.2 * np.cbrt(m / rho)
    a = np.sin(4 * pos[:, 0]) + pos[:, 2]
    return pos, h, m, rho, a


def test_from_sarracen_computes_sarracens_sph_interpolant():
    pd = pytest.importorskip("pandas")
    sarracen = pytest.importorskip("sarracen")
    from sarracen.interpolate import interpolate_3d_grid

    pos, h, m, rho, a = sph_particles()
    sdf = sarracen.SarracenDataFrame(pd.DataFrame(
        {"x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2], "h": h, "m": m, "rho": rho, "A": a}))
    scene = aarbf.from_sarracen(sdf, field="A")
    assert scene.kernel == "sph-cubic" and scene.attribute == "A"
    g = 12
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    volume = scene.grid(g)
    theta = interpolate_3d_grid(
        sdf, "A", normalize=True, backend="cpu", xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]),
        zlim=(lo[2], hi[2]), x_pixels=g, y_pixels=g, z_pixels=g)
    # sarracen's grid is [z, y, x]; ours [x, y, z].
    theta = np.asarray(theta).transpose(2, 1, 0)
    phi = volume[..., 0]
    keep = phi > 1e-3 * phi.max()
    assert keep.mean() > 0.5
    assert np.abs(theta[keep] / volume[..., 1][keep] - 1).max() < 1e-4


def test_from_sarracen_takes_a_mass_parameter_and_derives_densities():
    pd = pytest.importorskip("pandas")
    sarracen = pytest.importorskip("sarracen")
    pos, h, m, rho, a = sph_particles(500)
    sdf = sarracen.SarracenDataFrame(
        pd.DataFrame({"x": pos[:, 0], "y": pos[:, 1], "z": pos[:, 2], "h": h, "A": a}),
        params={"mass": float(m[0]), "hfact": 1.2})
    scene = aarbf.from_sarracen(sdf, field="A")
    direct = aarbf.Scene(
        aarbf.Particles(pos, attributes={"A": a, "rho": m[0] * (1.2 / h) ** 3},
                        smoothing_length=h),
        attribute="A", kernel="sph-cubic", mass=float(m[0]), density="rho",
        radius_attribute="smoothing_length")
    q = np.random.default_rng(1).random((200, 3))
    assert np.array_equal(scene.field(q), direct.field(q))


def test_from_yt_strips_units_to_code_units(caplog):
    yt = pytest.importorskip("yt")
    yt.set_log_level(40)
    pos, h, m, rho, a = sph_particles(800)
    data = {
        ("io", "particle_position_x"): pos[:, 0],
        ("io", "particle_position_y"): pos[:, 1],
        ("io", "particle_position_z"): pos[:, 2],
        ("io", "particle_mass"): m,
        ("io", "density"): rho,
        ("io", "smoothing_length"): 2 * h,  # yt's h is the kernel's whole support
        ("io", "temperature"): a,
    }
    ds = yt.load_particles(data, length_unit=3.0857e21, mass_unit=1.989e33,
                           bbox=np.array([[0.0, 1.0]] * 3))
    with caplog.at_level(logging.INFO, logger="aarbf"):
        scene = aarbf.from_yt(ds, ptype="io", field="temperature")
    assert "positions [code_length]" in caplog.text and "temperature [" in caplog.text
    assert scene.kernel == "sph-cubic" and scene.attribute == "temperature"
    # The same field as the arrays handed over directly (yt reorders particles: compare at
    # points, not particle by particle).
    direct = aarbf.Scene(
        aarbf.Particles(pos, attributes={"temperature": a, "particle_mass": m, "density": rho},
                        smoothing_length=2 * h),
        attribute="temperature", kernel="sph-cubic", mass="particle_mass", density="density",
        radius_attribute="smoothing_length", radius=1.0)
    q = np.random.default_rng(2).random((300, 3))
    ours, theirs = scene.field(q), direct.field(q)
    assert (ours[:, 0] > 0).all()
    np.testing.assert_allclose(ours, theirs, rtol=1e-12)
