"""The package computes what the CLI computes, bit for bit on the CPU backend: fields, images,
and scene files going both ways."""

import os
import signal
import threading
import time

import numpy as np
import pytest

import aarbf

STEP = 1
# The dam break's gravity points along -y.
FIELD = ["--attribute", "attribute", "--radius", "1.5%"]
RENDER = ["--width", 64, "--height", 64, "--spp", 2, "--backend", "cpu", "--up", "y"]


@pytest.fixture(scope="module")
def series(dambreak):
    return aarbf.open(dambreak)


@pytest.fixture(scope="module")
def scene(series):
    return aarbf.Scene(series, step=STEP, attribute="attribute", radius="1.5%")


def queries(series, m=3000):
    lo, hi = (np.array(b) for b in series.bounds)
    rng = np.random.default_rng(5)
    return lo + (hi - lo) * rng.random((m, 3))


def test_a_series_reads_every_step(series):
    assert len(series) == 3
    p = series[STEP]
    assert isinstance(p, aarbf.Particles) and len(p) == 20000
    assert p.names == ["attribute"]
    assert np.array_equal(series[-1].positions, series[2].positions)
    with pytest.raises(IndexError):
        series[3]
    assert series.times is None or len(series.times) == 3
    info = series.info()
    assert "3 steps" in info and "attribute 'attribute'" in info
    name, lo, hi = series.attributes[0]
    assert name == "attribute" and lo < hi
    # The series' range covers every step's.
    for k in range(3):
        values = series[k].attributes["attribute"]
        assert lo <= values.min() and values.max() <= hi


def test_field_values_equal_aarbf_field_bit_for_bit(scene, series, dambreak, cli, tmp_path):
    q = queries(series)
    np.save(tmp_path / "q.npy", q)
    cli("field", "--data", dambreak, "--step", STEP, *FIELD, "--backend", "cpu",
        "--queries", tmp_path / "q.npy", "--out", tmp_path / "f.npy")
    expected = np.load(tmp_path / "f.npy")
    got = scene.field(q)
    assert got.shape == (3000, 2)
    assert (got[:, 0] > 0).sum() > 100, "the queries must reach the fluid"
    assert np.array_equal(got, expected)
    # Float32 queries, as a file of float32 would give them.
    np.save(tmp_path / "q32.npy", q.astype(np.float32))
    cli("field", "--data", dambreak, "--step", STEP, *FIELD, "--backend", "cpu",
        "--queries", tmp_path / "q32.npy", "--out", tmp_path / "f32.npy")
    assert np.array_equal(scene.field(q.astype(np.float32)), np.load(tmp_path / "f32.npy"))


def test_particles_in_memory_give_the_fields_of_their_file(series, dambreak, cli, tmp_path):
    p = series[STEP]
    lo, hi = series.attributes[0][1:]
    mem = aarbf.Scene(
        aarbf.Particles(p.positions, attributes=p.attributes),
        attribute="attribute", attribute_range=(lo, hi), radius=0.02, cluster=16,
    )
    q = queries(series, 1000)
    np.save(tmp_path / "q.npy", q)
    cli("field", "--data", dambreak, "--step", STEP, "--attribute", "attribute",
        "--attribute-range", f"{lo!r},{hi!r}", "--radius", 0.02, "--cluster", 16,
        "--precision", "f64", "--backend", "cpu", "--queries", tmp_path / "q.npy",
        "--out", tmp_path / "f.npy")
    # The series' bounds (the file's three steps' there, the one step's here) place the cells
    # the sums run over, so the order of the terms, and the last bits, differ: in f64 the two
    # agree to rounding. (Particles saved beside a scene file and read back by the CLI give
    # the same bits: test_a_scene_saved_from_python_renders_the_same_with_the_cli.)
    got, expected = mem.field(q, precision="f64"), np.load(tmp_path / "f.npy")
    assert (got[:, 0] > 0).sum() > 100
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-300)


def test_grid_equals_aarbf_field_grid(scene, dambreak, cli, tmp_path):
    cli("field", "--data", dambreak, "--step", STEP, *FIELD, "--backend", "cpu",
        "--grid", "6x5x4", "--out", tmp_path / "g.npy")
    rows = np.load(tmp_path / "g.npy")
    volume = scene.grid((6, 5, 4))
    assert volume.shape == (6, 5, 4, 2)
    # The CLI's rows are x fastest: reshape(NZ, NY, NX, -1).
    assert np.array_equal(volume, rows.reshape(4, 5, 6, 2).transpose(2, 1, 0, 3))
    assert volume[..., 0].max() > 0
    # Explicit bounds: the same grid as the data's bounds.
    assert np.array_equal(scene.grid((6, 5, 4), bounds=scene.bounds), volume)


def render_cli(cli, dambreak, out, *extra):
    cli("render", "--data", dambreak, "--step", STEP, *FIELD, *RENDER, *extra,
        "--force", "--out", out)


def test_a_render_equals_aarbf_render_bit_for_bit(scene, dambreak, cli, tmp_path):
    render_cli(cli, dambreak, tmp_path / "cli.exr")
    render_cli(cli, dambreak, tmp_path / "cli.png")
    image = scene.render(width=64, height=64, spp=2, backend="cpu", up="y")
    assert isinstance(image, aarbf.Image) and isinstance(image, np.ndarray)
    assert image.shape == (64, 64, 4) and image.dtype == np.float32
    assert image[..., 3].max() > 0.1, "the fluid must show"
    # The CLI's linear float image (black background: the .exr holds the pixels as they are).
    assert np.array_equal(np.asarray(image), np.asarray(aarbf.read_image(tmp_path / "cli.exr")))
    image.save(tmp_path / "py.exr")
    image.save(tmp_path / "py.png")
    assert (tmp_path / "py.exr").read_bytes() == (tmp_path / "cli.exr").read_bytes()
    assert (tmp_path / "py.png").read_bytes() == (tmp_path / "cli.png").read_bytes()
    png = image._repr_png_()
    assert png.startswith(b"\x89PNG") and png == (tmp_path / "cli.png").read_bytes()


def test_cameras_equal_the_clis(scene, dambreak, cli, tmp_path):
    render_cli(cli, dambreak, tmp_path / "orbit.exr", "--camera-from", "30,20")
    orbit = scene.render(aarbf.Camera.orbit(30, 20, up="y"), width=64, height=64, spp=2, backend="cpu")
    assert np.array_equal(np.asarray(orbit), np.asarray(aarbf.read_image(tmp_path / "orbit.exr")))
    eye, at = (0.5, 0.4, 2.0), (0.5, 0.3, 0.5)
    cli("render", "--data", dambreak, "--step", STEP, *FIELD, *RENDER[:-2],
        "--camera", "0.5,0.4,2,0.5,0.3,0.5,0,1,0,35", "--force", "--out", tmp_path / "look.exr")
    look = scene.render(aarbf.Camera.look_at(eye, at, up=(0, 1, 0), fovy=35), width=64,
                        height=64, spp=2, backend="cpu")
    assert np.array_equal(np.asarray(look), np.asarray(aarbf.read_image(tmp_path / "look.exr")))
    assert not np.array_equal(np.asarray(look), np.asarray(orbit))


def test_a_scene_saved_from_python_renders_the_same_with_the_cli(series, cli, tmp_path):
    # Particles from memory, with a NaN row a reader of the user's data let through.
    p = series[STEP]
    pos = np.vstack([p.positions, [[np.nan, 0, 0]]])
    t = np.append(p.attributes["attribute"], 0.5)
    with pytest.warns(aarbf.AarbfWarning, match="dropped 1 of 20001"):
        mem = aarbf.Particles(pos, attributes={"attribute": t})
    scene = aarbf.Scene(mem, attribute="attribute", radius="1.5%", colormap="plasma")
    image = scene.render(aarbf.Camera.orbit(-40, 25, up="y"), width=48, height=40, spp=3,
                         integrator="marching", backend="cpu")
    scene.save(tmp_path / "s.toml")
    text = (tmp_path / "s.toml").read_text()
    assert "plasma" in text and "s_particles" in text and "marching" in text
    image.save(tmp_path / "py.exr")
    cli("render", "--scene", tmp_path / "s.toml", "--backend", "cpu", "--out", tmp_path / "cli.exr")
    assert (tmp_path / "cli.exr").read_bytes() == (tmp_path / "py.exr").read_bytes()
    # And read back by the package, the scene file renders it again.
    again = aarbf.Scene.load(tmp_path / "s.toml").render(backend="cpu")
    assert np.array_equal(np.asarray(again), np.asarray(image))
    with pytest.raises(OSError, match="exists"):
        scene.save(tmp_path / "s.toml")


def test_a_scene_file_from_the_cli_renders_the_same_in_python(dambreak, cli, tmp_path):
    render_cli(cli, dambreak, tmp_path / "cli.exr", "--colormap", "turbo",
               "--save-scene", tmp_path / "cli.toml")
    image = aarbf.Scene.load(tmp_path / "cli.toml").render(backend="cpu")
    assert np.array_equal(np.asarray(image), np.asarray(aarbf.read_image(tmp_path / "cli.exr")))


def test_a_long_render_releases_the_gil_and_stops_on_ctrl_c(scene):
    ticks = []
    stop = threading.Event()

    def tick():
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.01)

    ticker = threading.Thread(target=tick)
    ticker.start()
    timer = threading.Timer(1.0, lambda: os.kill(os.getpid(), signal.SIGINT))
    started = time.perf_counter()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            scene.render(width=64, height=64, spp=100000, backend="cpu", up="y")
    finally:
        stop.set()
        ticker.join()
        timer.cancel()
    elapsed = time.perf_counter() - started
    assert elapsed < 30, f"the render stopped {elapsed:.1f} s after it started"
    # Python ran beside the render: the ticker ticked while it rendered.
    assert len([t for t in ticks if t > started + 0.2]) > 10
    # The scene renders again afterwards.
    assert scene.render(width=8, height=8, spp=1, backend="cpu", up="y").shape == (8, 8, 4)


def test_a_periodic_box_gives_the_cli_field_and_no_seam(cli, tmp_path):
    # 997 particles in the box [0, 2) x [0, 1) x [0, 1), written as NumPy writes them.
    rng = np.random.default_rng(11)
    box = np.array([2.0, 1.0, 1.0])
    pos = rng.random((997, 3)) * box
    temp = np.sin(3.0 * pos[:, 0]) + pos[:, 2]
    np.save(tmp_path / "p.npy", np.column_stack([pos, temp]))
    q = rng.random((500, 3)) * box
    q[:100, 0] = 1e-9  # on the face x = 0 ...
    q[100:200] = q[:100]
    q[100:200, 0] = 2.0 - 1e-9  # ... and just inside the face x = 2: the same place
    np.save(tmp_path / "q.npy", q)
    cli("field", "--data", tmp_path / "p.npy", "--attribute", "col3", "--radius", 0.2,
        "--periodic", "2,1,1", "--backend", "cpu",
        "--queries", tmp_path / "q.npy", "--out", tmp_path / "f.npy")
    scene = aarbf.Scene(
        aarbf.Particles(pos, attributes={"col3": temp}),
        attribute="col3", radius=0.2, periodic=(2.0, 1.0, 1.0),
    )
    got = scene.field(q)
    assert np.array_equal(got, np.load(tmp_path / "f.npy"))
    # The two sets lie 2e-9 apart: equal to the field's change over that distance.
    assert np.allclose(got[:100], got[100:200], rtol=1e-5, atol=1e-6)
    # Without the box the faces differ: the test above would see a seam.
    open_box = aarbf.Scene(
        aarbf.Particles(pos, attributes={"col3": temp}),
        attribute="col3", radius=0.2, periodic=False,
    ).field(q)
    assert not np.allclose(open_box[:100, 0], open_box[100:200, 0], rtol=1e-3)
    with pytest.raises(ValueError, match="periodic"):
        aarbf.Scene(aarbf.Particles(pos), periodic="sideways")
