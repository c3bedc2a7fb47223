"""aarbf: attribute-aware RBF volume rendering of particle data from Python.

The package wraps the Rust library the ``aarbf`` command-line program uses (Morrical et al.,
"Attribute-Aware RBFs", IEEE VIS 2023): the same readers, the same scene file, the same field
and renderers. Arrays are handed over without an intermediate copy: float32 and float64 arrays
of any strides are read once into the double precision the library holds.

>>> import numpy as np, aarbf
>>> p = aarbf.Particles(np.random.rand(1000, 3), attributes={"T": np.random.rand(1000)})
>>> scene = aarbf.Scene(p, attribute="T", radius=0.1)
>>> phi_theta = scene.field(np.random.rand(5, 3))          # (5, 2): Phi, Theta
>>> image = scene.render(width=64, height=64, spp=4)        # (64, 64, 4) float32
>>> image.save("frame.png")
"""

from __future__ import annotations

import os
from typing import Any, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _aarbf
from ._aarbf import AarbfError, AarbfIOError, AarbfWarning, Camera, Series, backends

__all__ = [
    "AarbfError",
    "AarbfIOError",
    "AarbfWarning",
    "Camera",
    "Image",
    "Particles",
    "Scene",
    "Series",
    "backends",
    "from_sarracen",
    "from_yt",
    "open",
    "read_image",
]
__version__ = _aarbf.__version__

_PathLike = Union[str, "os.PathLike[str]"]


def _as_float(name: str, values: Any, ndim: int) -> np.ndarray:
    """`values` as a float32 or float64 array in native byte order, of `ndim` dimensions.

    float32 and float64 arrays pass through as they are (any strides, C or Fortran order: no
    copy here); integers convert to float64 (exact up to 2**53), other byte orders and float
    widths are converted once. Anything else is an AarbfError (a ValueError).
    """
    a = np.asarray(values)
    if a.dtype.kind in "iu":
        a = a.astype(np.float64)
    elif a.dtype.kind != "f":
        raise AarbfError(f"{name}: dtype {a.dtype} is not a real number type")
    elif a.dtype.itemsize not in (4, 8):
        a = a.astype(np.float64)
    if not a.dtype.isnative:
        a = a.astype(a.dtype.newbyteorder("="))
    if a.ndim != ndim:
        want = "(N, 3)" if ndim == 2 else "(N,)"
        raise AarbfError(f"{name} must be an {want} array, got shape {a.shape}")
    return a


Particles = _aarbf.Particles


def open(  # noqa: A001 (the yt convention: yt.load, aarbf.open)
    path: _PathLike,
    particle_type: Optional[Union[str, int]] = None,
    attribute: Optional[Union[str, Sequence[str]]] = None,
    format: Optional[str] = None,  # noqa: A002
    physical: bool = False,
    smoothing: Optional[str] = None,
    cache_mib: int = 2048,
) -> Series:
    """Opens a file, a directory or a glob as a time series: every format ``aarbf`` reads.

    ``particle_type`` picks an HDF5 snapshot's particles (gas, dm, stars, ... or 0..5);
    ``attribute`` reads only those attributes (all by default); ``format`` names the format
    where the extension does not; ``physical`` reads comoving quantities in physical units;
    ``smoothing="knn:32"`` derives smoothing lengths from neighbours. Returns a ``Series``:
    ``len()``, indexing (``series[3]`` is ``Particles``), ``.times``, ``.info()``.
    """
    attributes = [attribute] if isinstance(attribute, str) else attribute
    return Series(
        os.fspath(path),
        format=format,
        particle_type=None if particle_type is None else str(particle_type),
        physical=physical,
        attributes=None if attributes is None else list(attributes),
        smoothing=smoothing,
        cache_mib=cache_mib,
    )


class Image(np.ndarray):
    """A rendered image: an (H, W, 4) float32 array of linear RGBA (the background
    composited), with ``save`` and a Jupyter display."""

    background: tuple

    def __array_finalize__(self, obj: Any) -> None:
        self.background = getattr(obj, "background", (0.0, 0.0, 0.0))

    def save(self, path: _PathLike, bit_depth: int = 8, force: bool = True) -> None:
        """Writes the image as ``aarbf render --out`` does: ``.png`` (8-bit sRGB; 16-bit
        sRGB with alpha with ``bit_depth=16``) or ``.exr`` (linear float RGBA, premultiplied,
        the background taken out). No colour legend is drawn."""
        _aarbf.save_image(
            np.ascontiguousarray(self, dtype=np.float32),
            os.fspath(path),
            tuple(self.background),
            bit_depth,
            force,
        )

    def _repr_png_(self) -> bytes:
        return _aarbf.png_bytes(np.ascontiguousarray(self, dtype=np.float32))


def read_image(path: _PathLike) -> Image:
    """Reads an image ``aarbf`` wrote: an ``.exr`` as its linear float values, a PNG as its
    sRGB values over 0..1."""
    return np.asarray(_aarbf.read_image(os.fspath(path))).view(Image)


class Scene(_aarbf.Scene):
    """Particles (or a series) and a field over them, with what renders them.

    Parameters
    ----------
    data : Particles, list of Particles, Series, or None
        The particles (a list is a time series); None with ``scene_file`` takes the file's
        ``[data] path``.
    scene_file : path, optional
        A scene file (TOML) the CLI and the viewer read: its settings, the arguments over them.
    step, time : the step shown (an index, or the step nearest a time).
    attribute : the attribute the colour shows (default: the data's first).
    attribute_range : (lo, hi), or "series", "robust", "step", "robust-step".
    radius : a length, or a percentage of the bounding-box diagonal ("1.5%"); default from the
        smoothing lengths or the particles' spacing (``scene.radius`` says what it became).
    radius_attribute : a per-particle radius or smoothing-length attribute, times ``radius``.
    radius_map, density_map : a number, text as the CLI spells it ("ramp", "0:0.5,1:1"), or
        (x, y) control points.
    colormap : a preset (viridis, plasma, inferno, magma, turbo, cool-warm, grayscale) or a
        ParaView colour-map .json file.
    classification : "post" (average, then colour) or "pre".
    kernel : "gaussian-rbf" (the paper's), "sph-cubic", "sph-quintic", "sph-wendland-c2",
        "sph-wendland-c4".
    mass, density : an SPH kernel's masses and densities: an attribute's name or one value.
    cluster : particles per cluster box (1, 2, 4, 8, 16).
    periodic : True (the box an HDF5 snapshot's header states), False (an open box), a box
        length L or (LX, LY, LZ) (the box [0, L)); default: periodic where the snapshot's
        header says so. Particles near one face are felt across it, so the field has no seam.

    Automatic values are resolved as ``aarbf render`` resolves them, and said through the
    ``logging`` logger "aarbf" at INFO.
    """

    def __new__(
        cls,
        data: Any = None,
        scene_file: Optional[_PathLike] = None,
        *,
        step: Optional[int] = None,
        time: Optional[float] = None,
        attribute: Optional[str] = None,
        attribute_range: Any = None,
        radius: Optional[Union[float, str]] = None,
        radius_attribute: Optional[str] = None,
        radius_map: Any = None,
        density_map: Any = None,
        colormap: Optional[str] = None,
        classification: Optional[str] = None,
        kernel: Optional[str] = None,
        mass: Optional[Union[float, str]] = None,
        density: Optional[Union[float, str]] = None,
        cluster: Optional[int] = None,
        periodic: Optional[Union[bool, float, Tuple[float, float, float]]] = None,
    ) -> "Scene":
        if isinstance(data, (str, os.PathLike)):
            data = open(data)
        first = data[0] if isinstance(data, list) and data else data
        if (
            isinstance(first, _aarbf.Particles)
            and radius_attribute is None
            and "radius" in first.names
            and kernel in (None, "gaussian-rbf")
        ):
            # Particles(radius=...) gives each particle its radius: taken as it is.
            radius_attribute = "radius"
            if radius is None:
                radius = 1.0
        if isinstance(radius, (int, np.integer)) and not isinstance(radius, bool):
            radius = float(radius)
        return super().__new__(
            cls,
            data,
            scene_file=None if scene_file is None else os.fspath(scene_file),
            step=step,
            time=time,
            attribute=attribute,
            attribute_range=attribute_range,
            radius=radius,
            radius_attribute=radius_attribute,
            radius_map=radius_map,
            density_map=density_map,
            colormap=colormap,
            classification=classification,
            kernel=kernel,
            mass=mass,
            density=density,
            cluster=cluster,
            periodic=periodic,
        )

    def __init__(self, *args: Any, **kwargs: Any) -> None:  # arguments taken by __new__
        pass

    @classmethod
    def load(cls, path: _PathLike, **overrides: Any) -> "Scene":
        """The scene a scene file (TOML) describes, as ``aarbf render --scene`` reads it; keyword
        arguments override its settings."""
        return cls(None, scene_file=path, **overrides)

    def field(self, points: Any, backend: str = "cpu", precision: str = "auto") -> np.ndarray:
        """Phi (density) and Theta (the attribute field) at ``points`` ((M, 3)): an (M, 2)
        float64 array ((M, 4): Phi, r, g, b with pre-classification), exactly what ``aarbf
        field --queries`` computes. ``backend``: "cpu" (the f64 reference), "wgpu", "ash" or
        "auto"."""
        return super().field(_as_float("points", points, 2), backend, precision)

    def grid(
        self,
        shape: Union[int, Sequence[int]],
        bounds: Optional[Sequence[Sequence[float]]] = None,
        backend: str = "cpu",
        precision: str = "auto",
    ) -> np.ndarray:
        """Phi and Theta at the cell centres of a regular grid of ``shape`` = (nx, ny, nz) (or
        n for n^3) cells over ``bounds`` = ((xmin, ymin, zmin), (xmax, ymax, zmax)) (default:
        the data's bounds): an (nx, ny, nz, 2) float64 array indexed [i, j, k], as yt's
        covering grids are, the same values ``aarbf field --grid`` writes."""
        dims = [int(shape)] * 3 if np.isscalar(shape) else [int(s) for s in shape]
        if len(dims) != 3:
            raise AarbfError(f"grid shape must be (nx, ny, nz) or n, got {shape!r}")
        box = None
        if bounds is not None:
            lo, hi = bounds
            box = (tuple(float(v) for v in lo), tuple(float(v) for v in hi))
        rows = self.grid_rows(dims, box, backend, precision)
        nx, ny, nz = dims
        return rows.reshape(nz, ny, nx, rows.shape[1]).transpose(2, 1, 0, 3)

    def render(
        self,
        camera: Optional[Camera] = None,
        width: Optional[int] = None,
        height: Optional[int] = None,
        spp: Optional[int] = None,
        integrator: Optional[str] = None,
        backend: str = "auto",
        target_error: Optional[float] = None,
        time_budget: Optional[float] = None,
        **options: Any,
    ) -> Image:
        """Renders the scene to an (H, W, 4) float32 ``Image`` of linear RGBA.

        ``camera``: ``Camera.orbit(...)``, ``Camera.look_at(...)`` or ``Camera.benchmark(i,
        n)`` (default: the scene file's, else a default view of the data); ``width``,
        ``height`` (512), ``spp`` (16); ``integrator``: "ea" (emission-absorption), "marching",
        "delta", "ss-reference"; ``backend``: "auto", "cpu", "wgpu", "ash"; ``target_error``
        / ``time_budget``: render until the estimated error is at most E, or for S seconds
        (``spp`` is then chosen). Further options as ``aarbf render`` names them:
        ``seed``, ``noise``, ``step_size``, ``density_scale``, ``phi_ref``,
        ``color_by_density``, ``light`` (azimuth, elevation, intensity), ``ambient``,
        ``background`` (r, g, b), ``up``, ``precision``, ``error_metric``.

        The render runs without the GIL; Ctrl-C interrupts it between frames
        (KeyboardInterrupt). ``scene.save(path)`` afterwards writes the scene file that
        reproduces it with ``aarbf render --scene``.
        """
        array, background = self.render_array(
            camera=camera,
            width=width,
            height=height,
            spp=spp,
            integrator=integrator,
            backend=backend,
            target_error=target_error,
            time_budget=time_budget,
            **options,
        )
        image = np.asarray(array).view(Image)
        image.background = tuple(background)
        return image


def _code_units(array: Any) -> tuple:
    """A unyt array (yt) or pint/astropy quantity as (plain float array, unit text)."""
    units = getattr(array, "units", None)
    value = getattr(array, "d", None)  # unyt: the bare ndarray view
    if value is None:
        value = getattr(array, "value", None) if units is not None else None
    if value is None:
        value = getattr(array, "magnitude", None)
    if value is None:
        value = array
    return np.asarray(value), "" if units is None else str(units)


def from_yt(ds: Any, ptype: str = "gas", field: Optional[str] = None, **scene_options: Any) -> Scene:
    """A Scene of a yt dataset's particles of type ``ptype``: positions, smoothing lengths and
    ``field`` (a field of ``ptype``, e.g. "temperature"), converted to the dataset's code units
    and stripped of them (the units are said through the "aarbf" logger).

    Where the particles are SPH particles (a smoothing length, masses and densities), the
    scene takes an SPH cubic-spline kernel with their masses and densities, in yt's
    convention: yt's smoothing length is the kernel's whole support, so the global radius is
    1 (support = h, not aarbf's default 2h). Keyword arguments go to ``Scene`` and override
    these choices.
    """
    import logging

    ad = ds.all_data()
    units = ["code_length", "code_mass", "code_mass/code_length**3", "code_velocity",
             "code_time", "code_temperature", "code_specific_energy"]

    def code(name: str) -> tuple:
        q = ad[(ptype, name)]
        for unit in units:
            try:
                if q.units.dimensions == ds.quan(1.0, unit).units.dimensions:
                    q = q.to(unit)
                    break
            except Exception:  # a unit this dataset lacks: try the next
                continue
        return _code_units(q)

    positions, pos_units = code("particle_position")
    attributes: dict = {}
    said = [f"positions [{pos_units}]"]
    if field is not None:
        attributes[field], u = code(field)
        said.append(f"{field} [{u}]")
    fields = {f for (t, f) in ds.field_list if t == ptype}
    h = None
    if "smoothing_length" in fields:
        h, u = code("smoothing_length")
        said.append(f"smoothing_length [{u}]")
    sph = h is not None and "particle_mass" in fields and "density" in fields
    if sph:
        attributes["particle_mass"], u = code("particle_mass")
        said.append(f"particle_mass [{u}]")
        if field != "density":
            attributes["density"], u = code("density")
            said.append(f"density [{u}]")
    logging.getLogger("aarbf").info("from_yt: %s (code units)", ", ".join(said))
    particles = Particles(positions, attributes=attributes, smoothing_length=h, name=str(ds))
    if sph:
        scene_options.setdefault("kernel", "sph-cubic")
    if scene_options.get("kernel", "gaussian-rbf") != "gaussian-rbf":
        scene_options.setdefault("mass", "particle_mass")
        scene_options.setdefault("density", "density")
        scene_options.setdefault("radius_attribute", "smoothing_length")
        scene_options.setdefault("radius", 1.0)
    if field is not None:
        scene_options.setdefault("attribute", field)
    return Scene(particles, **scene_options)


def from_sarracen(sdf: Any, field: Optional[str] = None, **scene_options: Any) -> Scene:
    """A Scene of a sarracen SarracenDataFrame: positions (x, y, z), smoothing lengths (h) and
    ``field`` (a column), as plain numbers in the dataframe's code units (sarracen keeps no
    units), with sarracen's own kernel (M4 cubic spline unless the frame says otherwise),
    masses (the ``m`` column or ``sdf.params['mass']``) and densities (``rho`` or computed
    from h as sarracen does, rho = m (hfact / h)^3)."""
    xyz = [getattr(sdf, "xcol", "x"), getattr(sdf, "ycol", "y"), getattr(sdf, "zcol", "z")]
    positions = np.column_stack([np.asarray(sdf[c], dtype=np.float64) for c in xyz])
    hcol = getattr(sdf, "hcol", "h")
    h = np.asarray(sdf[hcol], dtype=np.float64)
    params = getattr(sdf, "params", None) or {}
    attributes: dict = {}
    if field is not None:
        attributes[field] = np.asarray(sdf[field], dtype=np.float64)
    mcol = getattr(sdf, "mcol", None) or ("m" if "m" in sdf.columns else None)
    if mcol is not None and mcol in sdf.columns:
        mass: Union[str, float] = "m"
        attributes["m"] = np.asarray(sdf[mcol], dtype=np.float64)
    elif "mass" in params:
        mass = float(params["mass"])
    else:
        raise AarbfError("from_sarracen: the dataframe has no masses (an 'm' column or params['mass'])")
    rcol = getattr(sdf, "rhocol", None) or ("rho" if "rho" in sdf.columns else None)
    if rcol is not None and rcol in sdf.columns:
        attributes["rho"] = np.asarray(sdf[rcol], dtype=np.float64)
    else:
        hfact = float(params.get("hfact", 1.2))
        m = attributes["m"] if isinstance(mass, str) else mass
        attributes["rho"] = m * (hfact / h) ** 3
    kernel = "sph-cubic"
    k = getattr(sdf, "kernel", None)
    name = type(k).__name__.lower() if k is not None else ""
    if "quintic" in name:
        kernel = "sph-quintic"
    elif "wendland" in name and "c4" not in name:
        kernel = "sph-wendland-c2"
    elif name and "cubic" not in name:
        raise AarbfError(
            f"from_sarracen: the dataframe's kernel {type(k).__name__} has no aarbf twin "
            "(sph-cubic, sph-quintic, sph-wendland-c2); pass kernel= to choose one"
        )
    scene_options.setdefault("kernel", kernel)
    scene_options.setdefault("mass", mass)
    scene_options.setdefault("density", "rho")
    scene_options.setdefault("radius_attribute", "smoothing_length")
    if field is not None:
        scene_options.setdefault("attribute", field)
    return Scene(Particles(positions, attributes=attributes, smoothing_length=h), **scene_options)
