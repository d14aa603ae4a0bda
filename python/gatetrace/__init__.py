"""gatetrace: a physically based GPU renderer for time-of-flight cameras, from Python.

Time is optical path length in metres (c = 1): a gate W weighs every light path by its length,
and a pixel measures the radiance (W m^-2 sr^-1) of the paths it sees, weighted by W. Gates are
strings in the command line's syntax (``"box:3.14..3.19"``, ``"transient:1.9,0.01,100"``) or
made by the constructors below (``box(3.14, 3.19)``, ``transient(1.9, 0.01, 100)``); lengths are
metres of optical path, and ``ps``, ``ns`` and ``mm`` convert other units to them.

    >>> import gatetrace
    >>> image = gatetrace.render("assets/scenes/cornell_box.gltf", gate="box:3.14..3.19", spp=64, res=(64, 64))
    >>> image.shape, image.dtype
    ((64, 64, 3), dtype('float32'))

A :class:`Renderer` keeps the device, the uploaded scene and the compiled kernels between renders:
a sweep over gates of one kind and bin count builds its kernels once. Images are float32 numpy
arrays ``[H, W, 3]`` (``[H, W, T, 3]`` for T transient bins), row 0 at the top: the layout of
``gatetrace render --out x.npy``. :func:`capture` renders a non-line-of-sight capture, as
``gatetrace render --nlos`` does. Bad arguments raise ValueError, a missing scene file
FileNotFoundError, device failures RuntimeError; Ctrl-C stops a render (KeyboardInterrupt).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Dict, Optional, Tuple, Union

import numpy as np

if not os.environ.get("XDG_RUNTIME_DIR"):
    # Mesa's Vulkan driver probes for a Wayland display when the device opens and prints an
    # error when this is unset; a headless render needs none (the command line does the same).
    import tempfile

    os.environ["XDG_RUNTIME_DIR"] = tempfile.gettempdir()

from . import _gatetrace
from ._gatetrace import Scene, describe_gate, device_name, kernels_built

__all__ = [
    "Scene",
    "Renderer",
    "Gate",
    "render",
    "capture",
    "none",
    "box",
    "gaussian",
    "cw",
    "table",
    "transient",
    "ps",
    "ns",
    "mm",
    "SPEED_OF_LIGHT",
    "describe_gate",
    "device_name",
    "kernels_built",
    "__version__",
]

__version__ = _gatetrace.version()

#: Speed of light (m/s): converts times of flight to optical path lengths.
SPEED_OF_LIGHT = 299_792_458.0


def ps(picoseconds: float) -> float:
    """Optical path length (m) light travels in `picoseconds` ps."""
    return picoseconds * 1e-12 * SPEED_OF_LIGHT


def ns(nanoseconds: float) -> float:
    """Optical path length (m) light travels in `nanoseconds` ns."""
    return nanoseconds * 1e-9 * SPEED_OF_LIGHT


def mm(millimetres: float) -> float:
    """`millimetres` mm in metres."""
    return millimetres * 1e-3


@dataclass(frozen=True)
class Gate:
    """A gate in the command line's syntax (``spec``); ``str(gate)`` gives it back."""

    spec: str

    def __str__(self) -> str:
        return self.spec

    def describe(self) -> str:
        """What the renderer understands the gate to be (ValueError when it is not one)."""
        return describe_gate(self.spec)


def _length(x: float) -> str:
    return repr(float(x))


def none() -> Gate:
    """The steady state: W = 1 for every path."""
    return Gate("none")


def box(start: float, end: float) -> Gate:
    """W = 1 for path lengths in [start, end) (m), else 0: an ideal gate."""
    return Gate(f"box:{_length(start)}..{_length(end)}")


def gaussian(mean: float, sigma: float) -> Gate:
    """W = exp(-(l - mean)^2 / (2 sigma^2)) (lengths in m), peak 1: an imperfect gate."""
    return Gate(f"gaussian:{_length(mean)},{_length(sigma)}")


def cw(frequency_hz: float, phase_deg: float, code: Optional[str] = None) -> Gate:
    """A CW-ToF gate: W = cos(2 pi f l / c + phase), signed, or with `code` (``"square"``,
    ``"ham3"``, ``"ham4:1"``..``"ham4:4"``, ``"mseq[:CHIPS]"``, ``"depthsel[:CHIPS[:N]]"``, see
    docs/gates.md) one period of that code's correlation, repeated."""
    spec = f"cw:{float(frequency_hz)!r},{float(phase_deg)!r}"
    return Gate(spec if code is None else f"{spec},{code}")


def table(path: Union[str, os.PathLike]) -> Gate:
    """W from a CSV file of rows ``length,weight`` (lengths may carry units), linear in between,
    0 outside."""
    return Gate(f"table:{os.fspath(path)}")


def transient(start: float, width: float, bins: int) -> Gate:
    """A transient cube: `bins` bins of `width` m of path each from `start` m; each bin's image
    integrates the radiance of the paths whose lengths fall in it."""
    return Gate(f"transient:{_length(start)},{_length(width)},{int(bins)}")


def _spec(gate: Union[str, Gate]) -> str:
    if isinstance(gate, Gate):
        return gate.spec
    if isinstance(gate, str):
        return gate
    raise TypeError(f"gate must be a string in the command line's syntax or a gatetrace.Gate, not {type(gate).__name__}")


class Renderer:
    """Renders one scene with one method, image size and bounce count, again and again.

    The device, the scene's upload and the compiled kernels are kept between renders: a render
    whose gate has the kind and bin count of the last one only moves the gate (as the viewer does
    when it scrubs tau), so gate sweeps compile kernels once. Every render starts afresh from its
    seed, so it equals the command line's ``gatetrace render`` with the same arguments.

    Args:
        scene: a :class:`Scene`, or the path of a glTF 2.0 file (.gltf, .glb) or a Mitsuba 3 XML
            scene. A Mitsuba scene's film, sampler and integrator (``Scene.settings``) give the
            defaults of `max_bounces` and `res` here, and of the gate, samples and seed of
            :meth:`render`.
        method: ``"path"`` (path tracing with next-event estimation), ``"direct"`` (bidirectional,
            direct connections), ``"ellipsoidal"`` (bidirectional, ellipsoidal connections: needs a
            gate), ``"combined"`` (both connection families in one estimator: needs a gate) or
            ``"auto"`` (path, direct or, with a gate, ellipsoidal after a pilot of each; builds its
            kernels for every render).
        max_bounces: most scattering vertices of a path (0: lights seen directly; None: the
            scene's, else 8).
        res: image size (width, height) in pixels (None: the scene's, else (256, 256)).
        rr_depth: Russian roulette from this many scattering vertices on (None: never).
        samples_per_pass: samples per pixel traced together (None: chosen from the image size).
        connections_per_query: ``ellipsoidal`` and ``combined``: points drawn from each
            ellipsoid query (1-8; None: 4).
        query_split, query_bottom_nodes, query_weights, query_tree: ``ellipsoidal``'s ellipsoid
            queries, as ``render --query-split``, ``--query-bottom-nodes``, ``--query-weights``
            and ``--query-tree`` (``"binary"`` or ``"wide"``).
        query_roulette: ``ellipsoidal``: the probability (1/16 to 1) with which a sample makes
            each ellipsoid query for paths of two or more scattering vertices, weighted by its
            inverse, as ``render --query-roulette`` (None: 1, every query; the command line's
            ``--time`` renders choose it by a pilot).
        medium_connections: ``path`` in homogeneous media behind a box or transient gate: also
            place scattering vertices where a ray meets the spheroid of a length drawn from the
            gate, as ``render --medium-connections`` (False: off).
    """

    def __init__(
        self,
        scene: Union[Scene, str, os.PathLike],
        *,
        method: str = "path",
        max_bounces: Optional[int] = None,
        res: Optional[Tuple[int, int]] = None,
        rr_depth: Optional[int] = None,
        samples_per_pass: Optional[int] = None,
        connections_per_query: Optional[int] = None,
        query_split: float = 1.0,
        query_bottom_nodes: int = 31,
        query_weights: str = "arcs",
        query_tree: str = "binary",
        query_roulette: Optional[float] = None,
        medium_connections: bool = False,
    ):
        if not isinstance(scene, Scene):
            scene = Scene.load(scene)
        settings = scene.settings
        if max_bounces is None:
            max_bounces = 8 if settings["max_bounces"] is None else settings["max_bounces"]
        if res is None:
            res = (256, 256) if settings["res"] is None else settings["res"]
        _check_count("max_bounces", max_bounces, 0)
        if rr_depth is not None:
            _check_count("rr_depth", rr_depth, 0)
        if samples_per_pass is not None:
            _check_count("samples_per_pass", samples_per_pass, 1)
        if connections_per_query is not None:
            _check_count("connections_per_query", connections_per_query, 1)
        width, height = _resolution(res)
        self.scene = scene
        self._native = _gatetrace.Renderer(
            scene,
            method=method,
            max_bounces=max_bounces,
            res=None if res is None else _resolution(res),
            rr_depth=rr_depth,
            samples_per_pass=samples_per_pass,
            connections_per_query=connections_per_query,
            query_split=float(query_split),
            query_bottom_nodes=query_bottom_nodes,
            query_weights=query_weights,
            query_tree=query_tree,
            query_roulette=None if query_roulette is None else float(query_roulette),
            medium_connections=bool(medium_connections),
        )

    def render(
        self,
        gate: Union[str, Gate, None] = None,
        *,
        spp: Optional[int] = None,
        seconds: Optional[float] = None,
        seed: Optional[int] = None,
    ) -> Tuple[np.ndarray, dict]:
        """Renders `gate` (None: the scene's, else ``"none"``) for `spp` samples per pixel (when
        neither is given: the scene's, else 64) or for `seconds` of rendering, from `seed` (None:
        the scene's, else 0; equal seeds and settings give identical images).

        Returns (image, metadata): a float32 array [H, W, 3] or [H, W, T, 3] of bin-integrated
        radiance (W m^-2 sr^-1) weighted by the gate, row 0 at the top; and the metadata the
        command line writes beside its outputs (scene, method, gate, spp, seed, timing, adapter,
        ...), numbers as numbers. The GIL is released while the device works.
        """
        settings = self.scene.settings
        if gate is None:
            gate = settings["gate"] or "none"
        if spp is None and seconds is None:
            spp = settings["spp"]
        if seed is None:
            seed = settings["seed"] or 0
        if spp is not None:
            _check_count("spp", spp, 1)
        if seconds is not None and not (isinstance(seconds, (int, float)) and seconds > 0):
            raise ValueError(f"seconds={seconds!r}: give a positive number of seconds")
        _check_count("seed", seed, 0)
        if seed >= 2**32:
            raise ValueError(f"seed={seed}: give a number below 2^32")
        image, pairs = self._native.render(_spec(gate), spp, None if seconds is None else float(seconds), seed)
        metadata = {key: json.loads(value) for key, value in pairs}
        if "warning" in metadata:
            import warnings

            warnings.warn(str(metadata["warning"]), RuntimeWarning, stacklevel=2)
        return image, metadata

    def __repr__(self) -> str:
        return repr(self._native)


def render(
    scene: Union[Scene, str, os.PathLike],
    gate: Union[str, Gate, None] = None,
    *,
    spp: Optional[int] = None,
    seconds: Optional[float] = None,
    seed: Optional[int] = None,
    method: str = "path",
    max_bounces: Optional[int] = None,
    res: Optional[Tuple[int, int]] = None,
    metadata: bool = False,
    **options,
):
    """Renders `scene` once: ``Renderer(scene, method=..., max_bounces=..., res=..., **options)
    .render(gate, spp=..., seconds=..., seed=...)``. Returns the image, or (image, metadata)
    with ``metadata=True``. For several renders of one scene, keep a :class:`Renderer`."""
    renderer = Renderer(scene, method=method, max_bounces=max_bounces, res=res, **options)
    image, meta = renderer.render(gate, spp=spp, seconds=seconds, seed=seed)
    return (image, meta) if metadata else image


def capture(
    scene: Union[Scene, str, os.PathLike],
    scan: Optional[str] = None,
    gate: Union[str, Gate, None] = None,
    *,
    spp: Optional[int] = None,
    seconds: Optional[float] = None,
    seed: Optional[int] = None,
    res: Optional[Tuple[int, int]] = None,
    max_bounces: Optional[int] = None,
    method: Optional[str] = None,
    relay_wall: Optional[str] = None,
    sensor_origin: Optional[Tuple[float, float, float]] = None,
    laser_origin: Optional[Tuple[float, float, float]] = None,
    laser_spot: Optional[Tuple[float, float]] = None,
    laser_grid: Optional[Tuple[int, int]] = None,
    laser_power: Optional[float] = None,
    count_first_last: bool = False,
    rr_depth: Optional[int] = None,
    samples_per_pass: Optional[int] = None,
    connections_per_query: Optional[int] = None,
    query_split: float = 1.0,
    query_bottom_nodes: int = 31,
    query_weights: Optional[str] = None,
    query_tree: str = "binary",
    target_pilot: Optional[int] = None,
    band_index: str = "auto",
    needle_guard: float = 1e-6,
    length_guard: float = 1e-5,
    allow_unsupported_materials: bool = False,
    parameters: Optional[Dict[str, str]] = None,
) -> Tuple[np.ndarray, dict]:
    """Renders a non-line-of-sight capture of `scene`: ``gatetrace render SCENE --nlos SCAN`` with
    the same options (``--relay-wall`` is ``relay_wall=``, ``--time`` is ``seconds=``, ...) and
    defaults, so equal arguments give the command line's capture bit for bit. docs/nlos.md
    explains captures at length. A Mitsuba XML scene that describes a capture (an
    ``nlos_capture_meter`` on its relay wall, a ``projector`` laser) gives every argument left as
    None: its scan, bins, grid, depth, samples, seed, wall, origins, aim and laser.

    Args:
        scene: a glTF 2.0 file (.gltf, .glb), a Mitsuba 3 XML scene, or a :class:`Scene` (its
            file is loaded again, prepared for the capture).
        scan: ``"single"`` (one laser spot for every sensed point), ``"confocal"`` (each sensed
            point lit on itself) or ``"exhaustive"`` (every spot of `laser_grid` with every
            sensed point); None: the file's capture's (required for other files).
        gate: in the command line's syntax or a :class:`Gate`, lengths in metres of optical path
            from the laser spot to the sensed point, e.g. ``transient(start, width, bins)``
            (None: the file's bins, else ``"none"``).
        spp, seconds, seed: samples per pixel (None: the file's, else 64 when neither is given)
            or seconds of rendering, and the seed (None: the file's, else 0; an exhaustive scan
            renders laser spot k from a seed of its own).
        res: the grid of sensed points on the relay wall, (width, height) (None: the file's, else
            (256, 256)).
        max_bounces: most scattering vertices of a path, the laser spot and the sensed point
            included (at least 2; 3: spot -> hidden point -> sensed point; None: the file's,
            else 8).
        method: ``"path"``, ``"direct"``, ``"ellipsoidal"`` or ``"combined"`` (None: ellipsoidal
            with a gate, path without).
        relay_wall: the relay wall's node (a glTF mesh with TEXCOORD_0 over [0, 1]^2; None: the
            file's capture's, else ``"relay_wall"``).
        sensor_origin, laser_origin: positions (x, y, z) in metres (None: the file's capture's,
            else the nodes named ``sensor_origin`` and ``laser_origin``, else ``nlos_origin``).
        laser_spot: ``single``: where the laser is aimed, texture coordinates (u, v) of the wall
            (None: the file's capture's aim, else (0.5, 0.5)).
        laser_grid: ``exhaustive``: the grid of laser spots, (width, height) (None: `res`).
        laser_power: the beam's power (W; None: the file's projector, else 1).
        count_first_last: count the laser -> spot and sensed point -> sensor segments in path
            lengths.
        rr_depth, samples_per_pass, connections_per_query, query_split, query_bottom_nodes,
            query_weights, query_tree, target_pilot, band_index, needle_guard, length_guard: as
            ``render --rr-depth`` ... ``--length-guard`` (None: the capture's defaults: 1 connection per
            query, ``"reflection"`` weights, a 256 spp target pilot for ellipsoidal on a
            transient gate; `band_index` ``"auto"``, ``"on"`` or ``"off"``).
        allow_unsupported_materials: render transmissive materials as opaque instead of
            refusing the scene.
        parameters: a Mitsuba scene's parameters (name to value; ``render --define``).

    Returns (data, metadata): a float32 array of bin-integrated radiance (W m^-2 sr^-1) leaving
    each sensed point towards the sensor origin, in the layout of the command line's .npy:
    ``[grid_y, grid_x, 3]`` or ``[grid_y, grid_x, T, 3]`` for T bins (``exhaustive``:
    ``[laser_y, laser_x, grid_y, grid_x, (T,) 3]``); and what the command line's JSON sidecar
    holds (the render's metadata, the sensed points and laser spots in metres, ...), numbers as
    numbers. Bad options raise ValueError naming the problem, a missing file FileNotFoundError;
    Ctrl-C stops the capture (KeyboardInterrupt).
    """
    path = scene.path if isinstance(scene, Scene) else scene
    if spp is not None:
        _check_count("spp", spp, 1)
    if seconds is not None and not (isinstance(seconds, (int, float)) and seconds > 0):
        raise ValueError(f"seconds={seconds!r}: give a positive number of seconds")
    if seed is not None:
        _check_count("seed", seed, 0)
        if seed >= 2**32:
            raise ValueError(f"seed={seed}: give a number below 2^32")
    if max_bounces is not None:
        _check_count("max_bounces", max_bounces, 0)
    optional_counts = (("rr_depth", rr_depth, 0), ("samples_per_pass", samples_per_pass, 1),
                       ("connections_per_query", connections_per_query, 1), ("target_pilot", target_pilot, 0))
    for name, value, least in optional_counts:
        if value is not None:
            _check_count(name, value, least)
    data, pairs = _gatetrace.capture(
        os.fspath(path),
        scan,
        None if gate is None else _spec(gate),
        spp=spp,
        seconds=None if seconds is None else float(seconds),
        seed=seed,
        method=method,
        max_bounces=max_bounces,
        res=None if res is None else _resolution(res),
        rr_depth=rr_depth,
        samples_per_pass=samples_per_pass,
        connections_per_query=connections_per_query,
        query_split=float(query_split),
        query_bottom_nodes=query_bottom_nodes,
        query_weights=query_weights,
        query_tree=query_tree,
        target_pilot=target_pilot,
        band_index=band_index,
        needle_guard=float(needle_guard),
        length_guard=float(length_guard),
        relay_wall=None if relay_wall is None else str(relay_wall),
        sensor_origin=None if sensor_origin is None else _point("sensor_origin", sensor_origin, 3),
        laser_origin=None if laser_origin is None else _point("laser_origin", laser_origin, 3),
        laser_spot=None if laser_spot is None else _point("laser_spot", laser_spot, 2),
        laser_grid=None if laser_grid is None else _resolution(laser_grid, "laser_grid"),
        laser_power=None if laser_power is None else float(laser_power),
        count_first_last=bool(count_first_last),
        allow_unsupported_materials=bool(allow_unsupported_materials),
        parameters=None if parameters is None else {str(k): str(v) for k, v in parameters.items()},
    )
    metadata = {key: json.loads(value) for key, value in pairs}
    if "warning" in metadata:
        import warnings

        warnings.warn(str(metadata["warning"]), RuntimeWarning, stacklevel=2)
    return data, metadata


def _point(name: str, value, n: int) -> tuple:
    try:
        point = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        point = ()
    if len(point) != n:
        raise ValueError(f"{name}={value!r}: give {n} numbers")
    return point


def _check_count(name: str, value, least: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, not {type(value).__name__}")
    if value < least:
        raise ValueError(f"{name}={value}: give at least {least}")


def _resolution(res, name: str = "res") -> Tuple[int, int]:
    try:
        width, height = res
    except (TypeError, ValueError):
        raise ValueError(f"{name}={res!r}: give (width, height) in pixels") from None
    _check_count(f"{name} width", width, 1)
    _check_count(f"{name} height", height, 1)
    return int(width), int(height)
