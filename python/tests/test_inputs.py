"""Arrays as other programs hand them over: dtypes, orders, strides, byte orders, shapes."""

import warnings

import numpy as np
import pytest

import aarbf


def cloud(n=500, seed=3):
    rng = np.random.default_rng(seed)
    return rng.random((n, 3)), rng.random(n)


def test_module_imports_and_lists_its_backends():
    found = {b["name"]: b for b in aarbf.backends()}
    assert set(found) == {"cpu", "wgpu", "ash"}
    assert found["cpu"]["available"] is True
    assert sum(b["auto"] for b in found.values()) == 1
    for b in found.values():
        assert ("device" in b) == b["available"]


def test_float64_positions_are_kept_bit_for_bit():
    pos, t = cloud()
    pos = pos * 1e6 + 1e12  # digits a float32 would lose
    p = aarbf.Particles(pos, attributes={"T": t})
    assert len(p) == 500
    assert np.array_equal(p.positions, pos)
    assert np.array_equal(p.attributes["T"], t)
    assert p.names == ["T"]


def test_float32_converts_exactly():
    pos, t = cloud()
    p = aarbf.Particles(pos.astype(np.float32), attributes={"T": t.astype(np.float32)})
    assert p.positions.dtype == np.float64
    assert np.array_equal(p.positions, pos.astype(np.float32).astype(np.float64))
    assert np.array_equal(p.attributes["T"], t.astype(np.float32).astype(np.float64))


@pytest.mark.parametrize(
    "make",
    [
        pytest.param(lambda a: np.asfortranarray(a), id="fortran-order"),
        pytest.param(lambda a: np.repeat(a, 2, axis=0)[::2], id="every-other-row"),
        pytest.param(lambda a: np.repeat(a, 2, axis=1)[:, ::2], id="strided-columns"),
        pytest.param(lambda a: a.astype(">f8"), id="big-endian-f8"),
        pytest.param(lambda a: a.astype(">f4"), id="big-endian-f4"),
        pytest.param(lambda a: a[::-1][::-1], id="negative-strides"),
    ],
)
def test_any_layout_gives_the_same_particles(make):
    pos, t = cloud()
    ref = aarbf.Particles(pos.astype(make(pos).dtype.newbyteorder("=")), attributes={"T": t})
    arr = make(pos)
    # The same values in another layout.
    assert np.array_equal(np.asarray(arr, dtype=np.float64), ref.positions)
    p = aarbf.Particles(arr, attributes={"T": make(t[:, None])[:, 0]})
    assert np.array_equal(p.positions, ref.positions)
    assert np.array_equal(p.attributes["T"], np.asarray(make(t[:, None])[:, 0], np.float64))


def test_a_field_is_the_same_whatever_the_layout():
    pos, t = cloud()
    q = np.random.default_rng(9).random((50, 3))
    a = aarbf.Scene(aarbf.Particles(pos, attributes={"T": t}), attribute="T", radius=0.2, cluster=4)
    b = aarbf.Scene(
        aarbf.Particles(np.asfortranarray(pos).astype(">f8"), attributes={"T": t[::-1][::-1]}),
        attribute="T",
        radius=0.2,
        cluster=4,
    )
    fa = a.field(q)
    assert fa.shape == (50, 2) and fa.dtype == np.float64
    assert (fa[:, 0] > 0).any()
    assert np.array_equal(fa, b.field(np.asfortranarray(q).astype(">f8")))


def test_integer_positions_and_attributes_convert_to_float64():
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [3, 3, 3]], dtype=np.int32)
    p = aarbf.Particles(pos, attributes={"id": np.arange(4, dtype=np.int64)})
    assert np.array_equal(p.positions, pos.astype(np.float64))
    assert np.array_equal(p.attributes["id"], [0.0, 1.0, 2.0, 3.0])


@pytest.mark.parametrize(
    "positions, words",
    [
        (np.zeros((5, 2)), "(N, 3)"),
        (np.zeros((5, 3, 1)), "(N, 3)"),
        (np.zeros(15), "(N, 3)"),
        (np.zeros((5, 4)), "(N, 3)"),
        (np.array([["a", "b", "c"]]), "not a real number"),
        (np.zeros((2, 3), dtype=complex), "not a real number"),
    ],
)
def test_a_wrong_shape_or_type_is_a_value_error_that_says_so(positions, words):
    with pytest.raises(aarbf.AarbfError, match=words.replace("(", r"\(").replace(")", r"\)")):
        aarbf.Particles(positions)
    assert issubclass(aarbf.AarbfError, ValueError)


def test_an_attribute_of_the_wrong_length_is_named():
    pos, t = cloud()
    with pytest.raises(ValueError, match="attribute 'T' has 499 values for 500 particles"):
        aarbf.Particles(pos, attributes={"T": t[:-1]})


def test_no_particles_is_an_error_as_the_cli_says_it():
    with pytest.raises(aarbf.AarbfError, match="no particles"):
        aarbf.Particles(np.empty((0, 3)))


def test_nan_positions_are_dropped_with_a_warning():
    pos, t = cloud()
    pos[7] = [np.nan, 0.5, 0.5]
    pos[11, 2] = np.inf
    t[20] = np.nan
    with pytest.warns(aarbf.AarbfWarning, match=r"dropped 3 of 500 particles \(2 with NaN/Inf positions, 1 with NaN/Inf 'T'\)"):
        p = aarbf.Particles(pos, attributes={"T": t})
    assert len(p) == 497
    keep = np.ones(500, bool)
    keep[[7, 11, 20]] = False
    assert np.array_equal(p.positions, pos[keep])
    assert np.array_equal(p.attributes["T"], t[keep])


def test_all_nan_is_an_error():
    with pytest.raises(aarbf.AarbfError, match="all 2 particles were dropped"):
        aarbf.Particles(np.full((2, 3), np.nan))


def test_one_particle_has_the_kernels_value_at_its_centre():
    p = aarbf.Particles(np.array([[1.0, 2.0, 3.0]]), attributes={"T": np.array([7.5])})
    scene = aarbf.Scene(p, attribute="T", radius=0.5)
    q = np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 3.25], [9.0, 9.0, 9.0]])
    # "auto" keeps Phi within 1e-5 (f32 where that suffices); "f64" is the exact reference.
    assert scene.field(q)[1, 0] == pytest.approx(np.exp(-1.125), rel=1e-5)
    f = scene.field(q, precision="f64")
    # exp(-0.5 (3 d / r)^2): 1 at the centre, exp(-1.125) half a radius away, 0 beyond r.
    assert f[0, 0] == 1.0 and f[0, 1] == 7.5
    assert f[1, 0] == pytest.approx(np.exp(-1.125), rel=1e-15)
    assert f[2, 0] == 0.0 and f[2, 1] == 0.0
    image = scene.render(width=16, height=16, spp=1, backend="cpu")
    assert image.shape == (16, 16, 4)
    assert image[..., 3].max() > 0


def test_non_finite_query_points_are_refused():
    pos, t = cloud()
    scene = aarbf.Scene(aarbf.Particles(pos, attributes={"T": t}), attribute="T", radius=0.2)
    with pytest.raises(aarbf.AarbfError, match="query 1 is not finite"):
        scene.field(np.array([[0.5, 0.5, 0.5], [np.nan, 0, 0]]))
    with pytest.raises(aarbf.AarbfError, match=r"\(N, 3\)"):
        scene.field(np.zeros((4, 2)))
    assert scene.field(np.empty((0, 3))).shape == (0, 2)


def test_bad_settings_are_value_errors_with_the_librarys_message():
    pos, t = cloud()
    p = aarbf.Particles(pos, attributes={"T": t})
    with pytest.raises(aarbf.AarbfError, match="no attribute 'nope'; the particles have: T"):
        aarbf.Scene(p, attribute="nope")
    with pytest.raises(aarbf.AarbfError, match="kernel 'bogus' is not one of: gaussian-rbf"):
        aarbf.Scene(p, kernel="bogus")
    with pytest.raises(aarbf.AarbfError, match="radius -1"):
        aarbf.Scene(p, radius=-1.0)
    with pytest.raises(aarbf.AarbfError, match=r"radius.map"):
        aarbf.Scene(p, radius_map="0:2")
    scene = aarbf.Scene(p, attribute="T", radius=0.2)
    with pytest.raises(aarbf.AarbfError, match="integrator 'bogus' is not one of"):
        scene.render(integrator="bogus")
    with pytest.raises(aarbf.AarbfError, match="each side must lie in"):
        scene.render(width=0, backend="cpu")


def test_an_sph_kernel_without_masses_says_what_it_needs():
    pos, t = cloud()
    p = aarbf.Particles(pos, attributes={"T": t}, smoothing_length=np.full(500, 0.15))
    with pytest.raises(aarbf.AarbfError, match="mass"):
        aarbf.Scene(p, attribute="T", kernel="sph-cubic")
    scene = aarbf.Scene(p, attribute="T", kernel="sph-cubic", mass=1.0, density=1.0)
    assert scene.kernel == "sph-cubic"
    assert scene.field(np.array([[0.5, 0.5, 0.5]]))[0, 0] > 0


def test_missing_files_are_os_errors():
    with pytest.raises(OSError) as e:
        aarbf.open("/nonexistent/data.vtp")
    assert isinstance(e.value, aarbf.AarbfIOError)
    assert "/nonexistent/data.vtp" in str(e.value)


def test_a_per_particle_radius_is_taken_as_it_is():
    pos = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0]])
    p = aarbf.Particles(pos, attributes={"T": np.array([1.0, 2.0])}, radius=np.array([1.0, 4.0]))
    scene = aarbf.Scene(p, attribute="T")
    f = scene.field(np.array([[1.5, 0, 0], [7.0, 0, 0]]), precision="f64")
    # The first particle reaches 1, the second 4: neither reaches 1.5 from the first... the
    # second reaches 7 (3 away, within 4).
    assert f[0, 0] == 0.0
    assert f[1, 0] == pytest.approx(np.exp(-0.5 * (3 * 3 / 4) ** 2), rel=1e-15)
    assert f[1, 1] == 2.0


def test_warnings_do_not_repeat_for_clean_data():
    pos, t = cloud()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        aarbf.Particles(pos, attributes={"T": t})
